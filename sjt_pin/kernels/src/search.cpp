// The set-point search of solve(): one Levenberg-Marquardt iteration (accept or reject the
// trial, the stall tests, the next step from the best point within the joint limits), and the
// class that holds a search's parameters, state and current point (search.hpp).
#include "search.hpp"

#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>

namespace sjt {

namespace {

// the Levenberg-Marquardt damping's factors down and up, and its range
constexpr double kNuDown = 3.0, kNuUp = 4.0, kNuMin = 1e-6, kNuMax = 1e8;
constexpr double kTurn = 2.0 * 3.14159265358979323846;
// a joint within this (rad, m) of one of its limits is held there (the quick stall test)
constexpr double kHeldTol = 1e-9;

// the smaller and larger of a and b, b when they do not compare (a NaN a): the search's
// arithmetic on a NaN error follows one path to its stall
inline double smaller(double a, double b) { return a < b ? a : b; }
inline double larger(double a, double b) { return a > b ? a : b; }

void finite_number(double value, const char* name) {
  if (!std::isfinite(value) || value < 0.0) {
    std::ostringstream out;
    out << name << " must be a finite number >= 0, got " << value;
    fail(out.str());
  }
}

}  // namespace

SetPointSearch::SetPointSearch(nb::handle sqrt_weight, nb::handle mask, Index coordinates,
                               nb::handle limit_q, nb::handle limit_v, nb::handle lower,
                               nb::handle upper, double mu, double tolerance, double floor,
                               bool scale, Index identity)
    : m(Array(sqrt_weight, "sqrt_weight", 1).size()),
      n(Array(mask, "mask", 1).size()),
      nq(coordinates),
      damping(mu),
      column_tol(tolerance),
      length(floor),
      scaled(scale),
      identity_rows(identity) {
  Array w(sqrt_weight, "sqrt_weight", 1), k(mask, "mask", 1);
  w.finite();
  k.finite();
  if (m < 1) fail("sqrt_weight must have at least one row");
  if (nq < 0) fail("nq must be >= 0");
  finite_number(damping, "damping");
  finite_number(column_tol, "column_tol");
  finite_number(length, "length");
  if (identity_rows != 0 && identity_rows != n) {
    std::ostringstream out;
    out << "identity_rows must be 0 or n = " << n << ", got " << identity_rows;
    fail(out.str());
  }
  IndexArray lq(limit_q, "limit_q", 1), lv(limit_v, "limit_v", 1);
  Array lo(lower, "lower", 1), hi(upper, "upper", 1);
  Index c = lq.size();
  lv.length(c);
  lo.length(c).no_nan();
  hi.length(c).no_nan();
  lq.within(0, nq);
  lv.within(0, n);
  sqrt_weight_ = w.vector();
  mask_ = k.vector();
  limit_q_.assign(lq.data(), lq.data() + c);
  limit_v_.assign(lv.data(), lv.data() + c);
  lower_ = lo.vector();
  upper_ = hi.vector();
  J_ = RowMatrix::Zero(m, n);
  e_ = Vector::Zero(m);
  q_ = Vector::Zero(nq);
  step_ = Vector::Zero(n);
  Jw_.resize(m, n);
  scaled_.resize(m, n);
  alpha_.resize(n);
  norms_.resize(n);
  root_.resize(n);
  fixed_.resize(n);
  free_.resize(static_cast<size_t>(n));
  v_.resize(m);
  Index mt = woodbury_rows();
  Index p = mt >= 0 ? mt : (m <= n ? m : n);
  rhs_.resize(mt >= 0 ? n : p);
  x_.resize(mt >= 0 ? n : p);
  diagonal_.resize(n);
  t_.resize(mt >= 0 ? 2 * mt : 0);
  normal_.resize(p, p);
  // (llt_ sizes itself on its first compute: Eigen's LLT(size) leaves its info unset, and a
  // copy of it reads that, undefined behaviour UBSan reports)
  start(true);
}

// The task rows above a posture task's identity rows when the normal matrix is solved as
// diagonal plus rank m_t (Woodbury: an m_t x m_t Cholesky, linear in n), where that is the
// cheaper solve; -1 otherwise.
Index SetPointSearch::woodbury_rows() const {
  if (identity_rows != n || m <= n) return -1;
  Index mt = m - n;
  return n * mt + mt * mt + 2 * mt + n <= 3 * n * n ? mt : -1;
}

void SetPointSearch::start(bool quick) {
  state = SearchState();
  state.nu = nu_start;
  state.best = std::numeric_limits<double>::infinity();
  state.quick = quick;
}

int SetPointSearch::iterate(const double* J, const double* e, const double* q) {
  double f = 0.0, e_sq = 0.0;
  for (Index i = 0; i < m; ++i) {
    double ew = sqrt_weight_[i] * e[i];
    f += 0.5 * ew * ew;
    if (i < error_rows) e_sq += e[i] * e[i];
  }
  bool first = state.iterations == 0;
  state.iterations += 1;
  if (first || f < state.f) {
    // (memmove: a caller may hand this search's own current point back)
    std::memmove(J_.data(), J, sizeof(double) * static_cast<size_t>(m * n));
    std::memmove(e_.data(), e, sizeof(double) * static_cast<size_t>(m));
    std::memmove(q_.data(), q, sizeof(double) * static_cast<size_t>(nq));
    state.f = f;
    state.e_sq = e_sq;
    if (!first) state.nu = larger(state.nu / kNuDown, kNuMin);
    if (e_sq <= tol * tol) return kConverged;
  } else {
    state.nu *= kNuUp;
    state.rejected = true;
  }
  if (f < progress * state.best || first) {
    state.best = smaller(f, state.f);
    state.stale = 0;
  } else {
    state.stale += 1;
  }
  if (state.stale >= stale_iters || state.nu > kNuMax || !std::isfinite(f)) return kSearchStalled;
  // the quick test (a stricter progress over fewer iterations): with a joint held at its
  // limit (heading for a minimum on the boundary of the box), or once a trial of the start has
  // been rejected (its damping found: Levenberg-Marquardt then converges fast or not at all;
  // before that, on a robot of metres-long links, the first damping holds a good start back
  // for several iterations)
  if (f < held_progress * state.held_best || first) {
    state.held_best = smaller(f, state.f);
    state.held_stale = 0;
  } else {
    state.held_stale += 1;
  }
  if (state.quick && state.held_stale >= held_iters && (state.rejected || held())) return kSearchStalled;
  limited_step();
  return kContinue;
}

// whether a joint of the current point sits on one of its position limits (to kHeldTol)
bool SetPointSearch::held() const {
  for (size_t k = 0; k < limit_q_.size(); ++k) {
    double x = q_[limit_q_[k]];
    if (x <= lower_[k] + kHeldTol || x >= upper_[k] - kHeldTol) return true;
  }
  return false;
}

// The damped step from the current point, scaled to the trust region max_step, within the
// limits: a joint that the step takes out of its range is fixed on its limit (a joint whose
// range spans a full turn wraps by 2 pi instead) and the others solved again, at most once
// per limited joint.
void SetPointSearch::limited_step() {
  Jw_.noalias() = sqrt_weight_.asDiagonal() * J_;
  double ew_sq = (sqrt_weight_.cwiseProduct(e_)).squaredNorm();
  double mu2 = damping * damping + state.nu * ew_sq;
  double length2 = length * length;
  for (Index j = 0; j < n; ++j) {
    free_[j] = mask_[j] != 0.0;
    fixed_[j] = 0.0;
  }
  // |W J_j|^2 of every column (task units^2)
  norms_.setZero();
  for (Index i = 0; i < m; ++i) {
    const double* row = Jw_.data() + i * n;
    for (Index j = 0; j < n; ++j) norms_[j] += row[j] * row[j];
  }
  for (size_t round = 0; round <= limit_q_.size(); ++round) {
    v_ = e_;
    for (Index j = 0; j < n; ++j)
      if (!free_[j] && mask_[j] != 0.0) v_.noalias() -= J_.col(j) * fixed_[j];
    for (Index j = 0; j < n; ++j) {
      double norm = free_[j] ? norms_[j] : 0.0;
      alpha_[j] = norm <= column_tol ? 0.0 : scaled ? 1.0 / larger(norm, length2) : 1.0;
    }
    damped_solve(mu2);
    double biggest = 0.0;
    for (Index j = 0; j < n; ++j) {
      if (!free_[j] && mask_[j] != 0.0) step_[j] = fixed_[j];
      biggest = larger(biggest, std::fabs(step_[j]));
    }
    if (biggest > max_step) step_ *= max_step / biggest;
    if (!clamp()) break;
  }
}

namespace {

// out = A^-1 rhs for the symmetric positive definite A (p x p) by Eigen's LLT: of fixed size
// for the usual 3 and 6 rows (a position or pose task), unrolled; of dynamic size otherwise
template <int P>
void fixed_llt_solve(const Eigen::MatrixXd& A, const double* rhs, double* out) {
  using Matrix = Eigen::Matrix<double, P, P>;
  using Vector = Eigen::Matrix<double, P, 1>;
  Eigen::LLT<Matrix> llt(Eigen::Map<const Matrix>(A.data()));
  Eigen::Map<Vector> x(out);
  x = llt.solve(Eigen::Map<const Vector>(rhs));
}

}  // namespace

void SetPointSearch::llt_solve(const double* rhs, double* out) {
  switch (normal_.rows()) {
    case 3:
      fixed_llt_solve<3>(normal_, rhs, out);
      return;
    case 6:
      fixed_llt_solve<6>(normal_, rhs, out);
      return;
    default:
      llt_.compute(normal_);
      Eigen::Map<Vector> x(out, normal_.rows());
      x = llt_.solve(Eigen::Map<const Vector>(rhs, normal_.rows()));
  }
}

// step = D J_w^T (J_w D J_w^T + mu2 I)^-1 (W v) with D = diag(alpha): an m x m solve when
// m <= n, else the same as sqrt(D) (sqrt(D) J_w^T J_w sqrt(D) + mu2 I)^-1 sqrt(D) J_w^T (W v)
// (n x n), and, above a posture task's identity rows, that n x n matrix as diagonal plus rank
// m_t through the Woodbury identity. (The products are coefficient-wise: on these few rows
// Eigen's blocked products cost more than they save.)
void SetPointSearch::damped_solve(double mu2) {
  Index mt = woodbury_rows();
  if (mt >= 0) {
    // U = (W_t J_t sqrt(D))^T (n x m_t), the diagonal Dg = D w_p^2 + mu2, and
    // x = (Dg + U U^T)^-1 rhs = Dg^-1 rhs - Dg^-1 U (I + U^T Dg^-1 U)^-1 U^T Dg^-1 rhs
    auto Ut = scaled_.topRows(mt);
    auto t = t_.head(mt), t2 = t_.tail(mt);
    for (Index j = 0; j < n; ++j) {
      double root = std::sqrt(alpha_[j]), wp = sqrt_weight_[mt + j] * sqrt_weight_[mt + j];
      double task = 0.0;
      for (Index a = 0; a < mt; ++a) task += Jw_(a, j) * sqrt_weight_[a] * v_[a];
      Ut.col(j) = root * Jw_.col(j).head(mt);
      root_[j] = root;
      double Dg = alpha_[j] * wp + mu2;
      diagonal_[j] = Dg > 0.0 ? 1.0 / Dg : 0.0;
      rhs_[j] = root * (task + wp * v_[mt + j]);
    }
    x_ = diagonal_.cwiseProduct(rhs_);
    t.noalias() = Ut.lazyProduct(x_);
    normal_.noalias() = (Ut * diagonal_.asDiagonal()).lazyProduct(Ut.transpose());
    normal_.diagonal().array() += 1.0;
    llt_solve(t.data(), t2.data());
    x_.noalias() -= diagonal_.asDiagonal() * Ut.transpose().lazyProduct(t2);
    step_ = root_.cwiseProduct(x_);
    return;
  }
  if (m <= n) {  // (plain loops on the contiguous rows: a few rows, a few joints)
    const double* W = Jw_.data();
    for (Index a = 0; a < m; ++a)
      for (Index b = 0; b <= a; ++b) {
        const double *wa = W + a * n, *wb = W + b * n;
        double acc = 0.0;
        for (Index j = 0; j < n; ++j) acc += alpha_[j] * wa[j] * wb[j];
        normal_(a, b) = normal_(b, a) = acc;
      }
    normal_.diagonal().array() += mu2;
    rhs_ = sqrt_weight_.cwiseProduct(v_);
    llt_solve(rhs_.data(), x_.data());
    for (Index j = 0; j < n; ++j) {
      double acc = 0.0;
      for (Index a = 0; a < m; ++a) acc += W[a * n + j] * x_[a];
      step_[j] = alpha_[j] * acc;
    }
    return;
  }
  root_ = alpha_.cwiseSqrt();
  scaled_.noalias() = Jw_ * root_.asDiagonal();
  for (Index i = 0; i < n; ++i)
    for (Index j = 0; j <= i; ++j)
      normal_(i, j) = normal_(j, i) = scaled_.col(i).dot(scaled_.col(j));
  normal_.diagonal().array() += mu2;
  rhs_.setZero();
  for (Index a = 0; a < m; ++a) rhs_ += (sqrt_weight_[a] * v_[a]) * scaled_.row(a).transpose();
  llt_solve(rhs_.data(), x_.data());
  step_ = root_.cwiseProduct(x_);
}

// Wrap or fix the free joints that q + step takes out of their range; whether one was fixed
bool SetPointSearch::clamp() {
  bool changed = false;
  for (size_t k = 0; k < limit_q_.size(); ++k) {
    Index qi = limit_q_[k], vi = limit_v_[k];
    if (!free_[vi]) continue;
    double lo = lower_[k], hi = upper_[k];
    double next = q_[qi] + step_[vi];
    if (lo <= next && next <= hi) continue;
    if (hi - lo >= kTurn) {
      double turn = next > hi ? -kTurn : kTurn;
      if (lo <= next + turn && next + turn <= hi) {
        step_[vi] += turn;
        continue;
      }
    }
    free_[vi] = 0;
    fixed_[vi] = smaller(larger(next, lo), hi) - q_[qi];
    changed = true;
  }
  return changed;
}

}  // namespace sjt
