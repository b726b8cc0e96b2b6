// The stage's projection (projection.hpp).
#include "projection.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace sjt {

namespace {

inline double clip(double v, double lo, double hi) { return std::min(std::max(v, lo), hi); }

}  // namespace

int Projection::inner(const Eigen::Ref<const Vector>& xb, const Eigen::Ref<const Vector>& lo,
                      const Eigen::Ref<const Vector>& hi, Index m, double scale) {
  const Index n = xb.size();
  auto G = G_.topRows(m);
  auto y = y_.head(m);
  auto off = off_.head(m);
  auto ridge = ridge_.head(m);
  bool exact = false;
  for (int it = 0;; ++it) {
    // the primal point of y and the dual gradient there
    z_.noalias() = G.transpose() * y;
    for (Index j = 0; j < n; ++j) {
      z_[j] = xb[j] - inv_[j] * z_[j];
      gx_[j] = clip(z_[j], lo[j], hi[j]);
    }
    grad_.head(m).noalias() = G * gx_;
    grad_.head(m) -= off + ridge.cwiseProduct(y);
    if (m == 0 || exact || grad_.head(m).cwiseAbs().maxCoeff() <= kTolerance * scale) return it;
    if (it == kInnerIterations) return it;
    // Newton: (G_F lam_F^-1 G_F^T + ridge) s = grad, F the joints strictly inside their box
    M_.topLeftCorner(m, m).setZero();
    for (Index j = 0; j < n; ++j)
      if (inv_[j] > 0.0 && z_[j] > lo[j] && z_[j] < hi[j])
        M_.topLeftCorner(m, m).selfadjointView<Eigen::Lower>().rankUpdate(G.col(j), inv_[j]);
    M_.topLeftCorner(m, m).diagonal() += ridge;
    llt_.compute(M_.topLeftCorner(m, m));
    if (llt_.info() != Eigen::Success) {
      // (rounding left M indefinite where the ridge is tiny beside its largest entries: a
      // ridge of 1e-12 of its diagonal's largest, else the iterate stands)
      const double bump = 1e-12 * M_.topLeftCorner(m, m).diagonal().cwiseAbs().maxCoeff();
      M_.topLeftCorner(m, m).diagonal().array() += bump > 0.0 ? bump : 1e-300;
      llt_.compute(M_.topLeftCorner(m, m));
      if (llt_.info() != Eigen::Success) return kInnerIterations;
    }
    step_.head(m) = llt_.solve(grad_.head(m));
    auto s = step_.head(m);
    // exact line search: phi'(t) = x(t) . G^T s - off . s - (ridge (y + t s)) . s, with
    // x(t) = clip(z - t w), w = lam^-1 G^T s: piecewise linear and decreasing in t
    gs_.noalias() = G.transpose() * s;
    const double c0 = off.dot(s) + ridge.cwiseProduct(y).dot(s);
    const double c1 = ridge.cwiseProduct(s).dot(s);
    events_.clear();
    double slope = -c1;  // d phi'/dt over the joints free at t = 0+
    double value = -c0;  // phi'(0)
    for (Index j = 0; j < n; ++j) {
      w_[j] = inv_[j] * gs_[j];
      value += gx_[j] * gs_[j];
      if (w_[j] == 0.0) continue;
      // joint j moves at -w_j: free between leaving one bound and reaching the other
      const double t_in = w_[j] > 0.0 ? (z_[j] - hi[j]) / w_[j] : (z_[j] - lo[j]) / w_[j];
      const double t_out = w_[j] > 0.0 ? (z_[j] - lo[j]) / w_[j] : (z_[j] - hi[j]) / w_[j];
      const double d = -w_[j] * gs_[j];  // its slope while free
      if (t_in <= 0.0 && t_out > 0.0) slope += d;  // free now
      if (t_in > 0.0) events_.emplace_back(t_in, static_cast<int>(j));       // becomes free
      if (t_out > 0.0) events_.emplace_back(t_out, static_cast<int>(-j - 1)); // clips
    }
    std::sort(events_.begin(), events_.end());
    double t = 0.0, best = std::numeric_limits<double>::quiet_NaN();
    bool crossed = false;  // whether the maximum lies past a joint's breakpoint
    for (const auto& [te, code] : events_) {
      const double at = value + slope * (te - t);
      if (at <= 0.0) {
        best = slope < 0.0 ? t - value / slope : te;
        break;
      }
      crossed = true;
      value = at;
      t = te;
      const Index j = code >= 0 ? code : -code - 1;
      slope += (code >= 0 ? 1.0 : -1.0) * (-w_[j] * gs_[j]);
    }
    if (std::isnan(best)) best = slope < 0.0 ? t - value / slope : std::max(t, 1.0);
    if (!(best > 0.0) || !std::isfinite(best)) return kInnerIterations;  // no ascent left
    y += best * s;
    // no joint changed side: the Newton step solved the problem of this set of clipped joints,
    // which is the problem itself (semismooth Newton's finite termination); one more pass
    // computes the point and checks it
    if (!crossed && std::abs(best - 1.0) <= 1e-6) exact = true;
  }
}

void Projection::polish(const Eigen::Ref<const RowMatrix>& C, const Eigen::Ref<const Vector>& d,
                        const Eigen::Ref<const RowMatrix>& A, const Eigen::Ref<const Vector>& b,
                        const Eigen::Ref<const Vector>& lo, const Eigen::Ref<const Vector>& hi) {
  const Index n = gx_.size(), c = C.rows(), w = static_cast<Index>(working_.size());
  if (c + w == 0) return;
  rows_.resize(c + w, n);
  residual_.resize(c + w);
  rows_.topRows(c) = C;
  residual_.head(c).noalias() = C * gx_ - d;
  for (Index a = 0; a < w; ++a) {
    rows_.row(c + a) = A.row(working_[a]);
    residual_[c + a] = A.row(working_[a]).dot(gx_) - b[working_[a]];
  }
  for (int pass = 0; pass < 2; ++pass) {
    // rows over the free joints, in the metric lam^-1
    for (Index j = 0; j < n; ++j) {
      const bool free = inv_[j] > 0.0 && gx_[j] > lo[j] && gx_[j] < hi[j];
      w_[j] = free ? inv_[j] : 0.0;
    }
    M_.topLeftCorner(c + w, c + w).noalias() = rows_ * w_.asDiagonal() * rows_.transpose();
    cod_.compute(M_.topLeftCorner(c + w, c + w));
    step_.head(c + w) = cod_.solve(residual_);
    z_.noalias() = rows_.transpose() * step_.head(c + w);
    for (Index j = 0; j < n; ++j) gx_[j] = clip(gx_[j] - w_[j] * z_[j], lo[j], hi[j]);
    residual_.head(c).noalias() = C * gx_ - d;
    for (Index a = 0; a < w; ++a)
      residual_[c + a] = A.row(working_[a]).dot(gx_) - b[working_[a]];
    if (residual_.cwiseAbs().maxCoeff() <= 1e-15 * (1.0 + gx_.cwiseAbs().maxCoeff())) break;
  }
}

Projection::WarmState Projection::warm_state() const {
  WarmState state;
  if (last_n_ < 0) return state;
  state.y = y_.head(last_r_ + last_c_);
  state.working = working_;
  state.n = last_n_;
  state.r = last_r_;
  state.c = last_c_;
  return state;
}

void Projection::set_warm_state(const WarmState& state) {
  working_.clear();
  if (state.n < 0) {
    forget();
    return;
  }
  last_n_ = state.n;
  last_r_ = state.r;
  last_c_ = state.c;
  working_ = state.working;
  if (y_.size() < state.y.size()) y_.conservativeResize(state.y.size());
  y_.head(state.y.size()) = state.y;
}

Projection::Projection() {
  const Eigen::MatrixXd one = Eigen::MatrixXd::Identity(1, 1);
  cod_.compute(one);
  llt_.compute(one);
}

ProjectionReport Projection::solve(
    const Eigen::Ref<const Vector>& xb, const Eigen::Ref<const Vector>& lam,
    const Eigen::Ref<const RowMatrix>& B, const Eigen::Ref<const Vector>& lo,
    const Eigen::Ref<const Vector>& hi, const Eigen::Ref<const RowMatrix>& A,
    const Eigen::Ref<const Vector>& b, const Eigen::Ref<const RowMatrix>& C,
    const Eigen::Ref<const Vector>& d, Eigen::Ref<Vector> x, bool warm) {
  const Index n = xb.size(), r = B.rows(), c = C.rows(), k = A.rows();
  const Index most = r + c + k;
  if (G_.rows() < most || G_.cols() != n) G_.resize(std::max(most, G_.rows()), n);
  if (M_.rows() < most) M_.resize(most, most);
  for (Vector* v : {&grad_, &step_, &off_, &ridge_})
    if (v->size() < most) v->resize(most);
  if (y_.size() < most) y_.conservativeResize(most);
  for (Vector* v : {&inv_, &z_, &gx_, &w_, &gs_}) v->resize(n);
  events_.reserve(2 * n);
  working_.reserve(k);
  for (Index j = 0; j < n; ++j) inv_[j] = std::isfinite(lam[j]) ? 1.0 / lam[j] : 0.0;

  const bool same = warm && last_n_ == n && last_r_ == r && last_c_ == c;
  if (!same) {
    y_.setZero();
    working_.clear();
  } else {
    // keep the working rows that still exist, each once (at most k: the buffers hold r + c + k)
    working_.erase(std::remove_if(working_.begin(), working_.end(),
                                  [k](int i) { return i < 0 || i >= k; }),
                   working_.end());
    std::sort(working_.begin(), working_.end());
    working_.erase(std::unique(working_.begin(), working_.end()), working_.end());
    y_.segment(r + c, working_.size()).setZero();  // (their multipliers start anew)
  }
  last_n_ = n;
  last_r_ = r;
  last_c_ = c;
  G_.topRows(r) = B;
  G_.middleRows(r, c) = C;
  off_.head(r).noalias() = B * xb;
  ridge_.head(r).setOnes();
  // the rows' ridge: 1e-12 of the least curvature a row can have in the metric,
  // |row|^2 / (max lam + |B|^2): a row stiff in the task's metric gets a multiplier of that
  // metric's size, and what the ridge lets it break (ridge times multiplier) stays negligible
  double stiffness = B.squaredNorm();
  for (Index j = 0; j < n; ++j)
    if (std::isfinite(lam[j])) stiffness = std::max(stiffness, lam[j] + B.squaredNorm());
  const double row_ridge = kRidge / std::max(stiffness, 1e-300);
  for (Index i = 0; i < c; ++i) ridge_[r + i] = row_ridge * (1e-300 + C.row(i).squaredNorm());

  // the gradient's scale, for a tolerance that does not depend on the units
  double scale = 0.0;
  if (r) scale = std::max(scale, off_.head(r).cwiseAbs().maxCoeff());
  if (c) scale = std::max(scale, d.cwiseAbs().maxCoeff());
  for (Index i = 0; i < k; ++i)  // (a row with b = inf bounds nothing: not a scale)
    if (std::isfinite(b[i])) scale = std::max(scale, std::abs(b[i]));
  if (!(scale > 0.0)) scale = 1.0;
  ProjectionReport report;
  bool settled = false;
  for (int outer = 0; outer < 3 * k + 10; ++outer) {
    const Index m = r + c + static_cast<Index>(working_.size());
    off_.segment(r, c) = d;
    for (size_t a = 0; a < working_.size(); ++a) {
      const Index i = working_[a];
      G_.row(r + c + a) = A.row(i);
      off_[r + c + a] = b[i];
      ridge_[r + c + a] = row_ridge * (1e-300 + A.row(i).squaredNorm());
    }
    const int it = inner(xb, lo, hi, m, scale);
    report.iterations += it + 1;
    if (it >= kInnerIterations) report.converged = false;
    {
      // a working row whose multiplier turned negative leaves
      Index worst = -1;
      double most_negative = -kTolerance * (1.0 + (m ? y_.head(m).cwiseAbs().maxCoeff() : 0.0));
      for (size_t a = 0; a < working_.size(); ++a)
        if (y_[r + c + a] < most_negative) {
          most_negative = y_[r + c + a];
          worst = static_cast<Index>(a);
        }
      if (worst >= 0) {
        working_.erase(working_.begin() + worst);
        for (Index a = r + c + worst; a + 1 < m; ++a) y_[a] = y_[a + 1];
        continue;
      }
      // the most violated row outside joins: broken by more than rounding, measured in the
      // row's own units (a measure in the metric would hide a row that a joint of tiny
      // curvature dominates - one its box pins, such as a joint no task moves)
      Index join = -1;
      double violation = 0.0;
      const double size = gx_.cwiseAbs().maxCoeff();
      for (Index i = 0; i < k; ++i) {
        if (std::find(working_.begin(), working_.end(), static_cast<int>(i)) != working_.end())
          continue;
        const double norm = A.row(i).norm();
        const double broken = A.row(i).dot(gx_) - b[i];
        if (!(broken > kRowTolerance * (std::abs(b[i]) + norm * size))) continue;
        const double v = broken / (norm + 1e-300);
        if (v > violation) {
          violation = v;
          join = i;
        }
      }
      if (join >= 0) {
        working_.push_back(static_cast<int>(join));
        y_[m] = 0.0;
        continue;
      }
    }
    // the working set is settled; the ridge that keeps the dual regular leaves the equalities
    // and working rows broken by the ridge times their multiplier: the least correction of the
    // joints strictly inside their box in the metric diag(lam) meets them exactly (a polish of
    // the size of that breach)
    polish(C, d, A, b, lo, hi);
    settled = true;
    break;
  }
  if (!settled) report.converged = false;
  x = gx_;
  report.rows_active = static_cast<int>(working_.size());
  return report;
}

}  // namespace sjt

// -- Python entry, for the tests (tests/test_projection.py checks it against quadprog)
#include <nanobind/eigen/dense.h>
#include <nanobind/stl/tuple.h>

#include "registry.hpp"

namespace sjt {

void register_projection(nb::module_& m) {
  m.def(
      "project",
      [](const Vector& xb, const Vector& lam, const RowMatrix& B, const Vector& lo,
         const Vector& hi, const RowMatrix& A, const Vector& b, const RowMatrix& C,
         const Vector& d) {
        const Index n = xb.size();
        if (lam.size() != n || lo.size() != n || hi.size() != n || B.cols() != n ||
            A.cols() != n || C.cols() != n || b.size() != A.rows() || d.size() != C.rows())
          fail("project: the arrays do not fit (xb, lam, lo, hi: n; B, A, C: n columns)");
        for (Index j = 0; j < n; ++j)
          if (!(lam[j] > 0.0) || lo[j] > hi[j]) fail("project: lam > 0 and lo <= hi, per joint");
        Projection p;
        Vector x(n);
        ProjectionReport r = p.solve(xb, lam, B, lo, hi, A, b, C, d, x);
        return std::make_tuple(x, r.iterations, r.converged);
      },
      nb::arg("xb"), nb::arg("lam"), nb::arg("B"), nb::arg("lo"), nb::arg("hi"), nb::arg("A"),
      nb::arg("b"), nb::arg("C"), nb::arg("d"),
      "project(xb, lam, B, lo, hi, A, b, C, d) -> (x, iterations, converged): the stage's "
      "projection (min 1/2 |x - xb|^2_(diag(lam) + B^T B) within the box, A x <= b, C x = d).");
}

}  // namespace sjt
