// The CLIK mappings and their metrics (method.hpp).
#include "method.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace sjt {

namespace {

// eigenvalues below this fraction of the largest are zero (the eigen-decomposition's accuracy)
constexpr double kEigenFloor = 1e3 * std::numeric_limits<double>::epsilon();
// power of the loop bound: lambda_max <= (tr A^(2^(P+1)))^(1/2^(P+1))
constexpr int kBoundProducts = 2;

// The stall the escape watches: the loop gain along the command k = K e_w over the trace,
// sum_j s_j (J_j^T k)^2 / (|k|^2 trace), trace = sum_j s_j |J_j|^2 (the caller's), over the
// first `rows` rows (0 without a command or a moving column)
double stall_ratio(const Eigen::Ref<const RowMatrix>& Jw, const Vector& k, const Vector& s,
                   double trace, Index rows) {
  const double k_sq = k.head(rows).squaredNorm();
  double stall = 0.0;
  for (Index j = 0; j < Jw.cols(); ++j) {
    const double task = Jw.col(j).head(rows).dot(k.head(rows));
    stall += s[j] * task * task;
  }
  return k_sq > 0.0 && trace > 0.0 ? stall / (k_sq * trace) : 0.0;
}

}  // namespace

double Method::loop_bound(const Eigen::Ref<const Eigen::MatrixXd>& A) {
  const double trace = A.trace();
  if (!(trace > 0.0)) return 0.0;
  work_ = A / trace;
  double log_scale = std::log(trace);
  for (int t = 0; t < kBoundProducts; ++t) {
    const double frob = work_.squaredNorm();
    work2_.noalias() = work_ * work_;
    work_ = work2_ / frob;
    log_scale = 2.0 * log_scale + std::log(frob);
  }
  const double frob = work_.squaredNorm();
  return std::exp((2.0 * log_scale + std::log(frob)) / std::pow(2.0, kBoundProducts + 1));
}

double Method::symmetric_top(const Eigen::MatrixXd& A) {
  if (A.rows() == 0) return 0.0;
  work_ = 0.5 * (A + A.transpose());
  eigen_.compute(work_, Eigen::EigenvaluesOnly);
  return eigen_.eigenvalues()[A.rows() - 1];
}

Method::Method() {
  const Eigen::MatrixXd one = Eigen::MatrixXd::Identity(1, 1);
  llt_.compute(one);
  eigen_.compute(one);
  metric_llt_.compute(one);
}

void Method::prepare(const Eigen::Ref<const RowMatrix>& Jw, const Eigen::Ref<const Vector>& ew,
                     const Eigen::Ref<const Vector>& k, Index error_rows, double dt,
                     MethodStep& out, bool gain) {
  const Index m = Jw.rows(), n = Jw.cols();
  out.alpha.setZero(n);
  out.s.resize(n);
  out.lam.resize(n);
  out.e_sq = 0.0;  // (the caller fills e_sq and ff_sq: it has the unweighted rows)
  out.ew_sq = ew.head(error_rows).squaredNorm();
  norms_.resize(n);
  for (Index j = 0; j < n; ++j) norms_[j] = Jw.col(j).squaredNorm();
  const Vector& norms = norms_;
  if (p.family == Family::transpose) {
    double trace = 0.0, curvature = 0.0, alpha_max = 0.0;
    for (Index j = 0; j < n; ++j) {
      const double norm = norms[j];
      const bool moves = norm > p.column_tol;
      out.alpha[j] = moves ? 1.0 / std::max(norm, p.length2) : 0.0;
      out.s[j] = p.scaled ? out.alpha[j] : (moves ? 1.0 : 0.0);
      trace += out.s[j] * norm;
      if (moves) curvature = std::max(curvature, std::sqrt(norm) * out.s[j]);
      alpha_max = std::max(alpha_max, out.alpha[j]);
    }
    out.trace = trace;
    v_.noalias() = k.cwiseProduct(ew);
    out.stall = stall_ratio(Jw, v_, out.s, trace, error_rows);
    out.loop_bound = 1.0;
    if (!p.auto_gain || !gain) {
      out.gain = 1.0;
    } else if (p.damped_feedback) {
      out.gain = p.gain_factor / dt;
    } else {
      scaled_.noalias() = Jw * out.s.asDiagonal();
      gram_.noalias() = scaled_ * Jw.transpose();
      const double bound = loop_bound(gram_) + p.lm * std::sqrt(out.ew_sq) * curvature;
      out.gain = bound > 0.0 ? p.gain_factor / (dt * bound) : 0.0;
      out.loop_bound = bound;
    }
    if (p.damped_feedback) {  // (the damped solve is on the unit columns, JT's too)
      out.damping = p.mu * p.mu + p.lm * std::sqrt(out.ew_sq * alpha_max);
      for (Index j = 0; j < n; ++j)
        out.lam[j] = out.alpha[j] > 0.0 ? out.damping / out.alpha[j] : kInf;
    } else {
      out.damping = p.mu * p.mu;
      for (Index j = 0; j < n; ++j) out.lam[j] = out.s[j] > 0.0 ? 1.0 / out.s[j] : kInf;
    }
    return;
  }
  // least squares: JP (lambda = 0) and DLS
  out.s = (norms.array() > 0.0).cast<double>();
  out.trace = 0.0;
  // the stall the escape watches, as JT's (S = I). Near a singular minimum out of reach the
  // damped and pseudoinverse steps shrink with the lost direction's singular value: without it
  // Kinova stretched toward targets out of reach crept at 5e-3 to 3e-2 rad/s after 30 s (DLS,
  // JP; `sjt-pin bench settle`), where the escape's test finds the minimum and the arm rests
  v_.noalias() = k.cwiseProduct(ew);
  double trace = 0.0;  // (S is the mask of the moving columns: the sum of their norms)
  for (Index j = 0; j < n; ++j) trace += norms[j];
  out.stall = stall_ratio(Jw, v_, out.s, trace, error_rows);
  out.loop_bound = 1.0;
  out.gain = p.auto_gain ? p.gain_factor / dt : 1.0;
  out.damping = p.mu * p.mu + p.lm * std::sqrt(out.ew_sq);
  const double floor = 1e-6 * std::max(norms.sum() / std::max<Index>(n, 1), 1e-300);
  for (Index j = 0; j < n; ++j) out.lam[j] = out.s[j] > 0.0 ? std::max(out.damping, floor) : kInf;
}

bool Method::objective_rows(const Eigen::Ref<const RowMatrix>& Jw, RowMatrix& B) const {
  if (p.family == Family::transpose && !(p.damped_feedback && p.scaled)) return false;
  B = Jw;
  return true;
}

void Method::metric(const Eigen::Ref<const RowMatrix>& Jw, const MethodStep& step,
                    const Eigen::Ref<const Vector>& t, double beta, RowMatrix& B) {
  const Index m = Jw.rows(), n = Jw.cols();
  if (!metric_ready_ || metric_.rows() != m) {
    // G: I + l (J S J^T)^-1 (damped forms), (J S J^T)^-1 (transpose feedback), I (JP); the
    // inverse regularised by delta, which bounds G: 1e-9 of the mean eigenvalue and 1e-3 of l
    // (damped forms); 1e-2 of the mean eigenvalue (transpose feedback, where nothing else bounds
    // it: with 1e-9, the nearest feasible velocity at a wrist's position limit was so flat along
    // the directions J nearly loses that Baxter's arm in mm and in m, the same inputs up to
    // rounding, parted by 4e-3 to 1e-2 rad over 2.5 s)
    const bool transpose = p.family == Family::transpose && !p.damped_feedback;
    const double l = transpose ? 1.0 : step.damping;
    metric_.setIdentity(m, m);
    if (l > 0.0 && m > 0) {
      scaled_.noalias() = Jw * (p.family == Family::transpose && p.damped_feedback ? step.alpha
                                                                                   : step.s)
                                   .asDiagonal();
      gram_.noalias() = scaled_ * Jw.transpose();
      const double trace = gram_.trace();
      const double delta =
          std::max((transpose ? 1e-2 : 1e-9) * std::max(trace, 1e-300) / m,
                   transpose ? 0.0 : 1e-3 * l);
      gram_.diagonal().array() += delta;
      llt_.compute(gram_);
      work_.setIdentity(m, m);
      llt_.solveInPlace(work_);
      if (transpose) metric_ = work_;
      else metric_ += l * work_;
    }
    // mu_T: the task part 1e6 times the joint metric, on average over the moving joints
    double joints = 0.0, count = 0.0;
    for (Index j = 0; j < n; ++j)
      if (std::isfinite(step.lam[j])) joints += step.lam[j], count += 1.0;
    metric_llt_.compute(metric_);
    scaled_.noalias() = metric_llt_.matrixU() * Jw;
    const double task = count > 0.0 ? scaled_.squaredNorm() / count : 0.0;
    task_weight_ = task > 0.0 ? MethodParameters::kTaskFirst * joints / task : 1.0;
    metric_ready_ = true;
  }
  // G' = G + beta (G - G t t^T G / (t^T G t))
  B.resize(m, n);
  if (m == 0) return;
  bool directed = false;
  if (beta > 0.0) {
    gt_.noalias() = metric_ * t;
    const double tgt = t.dot(gt_);
    if (tgt > 0.0) {
      directed_ = (1.0 + beta) * metric_;
      directed_.noalias() -= (beta / tgt) * gt_ * gt_.transpose();
      llt_.compute(directed_);
      directed = true;
    }
  }
  // B^T B = J^T G' J (G' = G: the factor computed above)
  B.noalias() = (directed ? llt_.matrixU() : metric_llt_.matrixU()) * Jw;
  B *= std::sqrt(task_weight_);
}

void Method::solve(const Eigen::Ref<const RowMatrix>& Jw, const Eigen::Ref<const Vector>& v,
                   const Eigen::Ref<const Vector>& s, double l, bool pseudo,
                   Eigen::Ref<Vector> out) {
  factor(Jw, s, l, pseudo);
  apply(Jw, v, out);
}

void Method::factor(const Eigen::Ref<const RowMatrix>& Jw, const Eigen::Ref<const Vector>& s,
                    double l, bool pseudo) {
  const Index m = Jw.rows(), n = Jw.cols();
  damping_ = l;
  if (m == 0) {
    solve_ = Solve::none;
    return;
  }
  if (m <= n) {
    scaled_.noalias() = Jw * s.asDiagonal();
    gram_.noalias() = scaled_ * Jw.transpose();
    solve_ = Solve::rows_cholesky;
    if (!pseudo) {
      gram_.diagonal().array() += l;
      llt_.compute(gram_);
      return;
    }
    // the pseudoinverse on the eigenvalues above the cutoff, damped by l: by Cholesky when
    // the smallest eigenvalue is certainly above it (lambda_min >= 1 / tr(A^-1)), else by
    // the eigen-decomposition
    const double top = gram_.diagonal().maxCoeff();
    cutoff_ = std::max(p.rcond * p.rcond, kEigenFloor) * top;
    llt_.compute(gram_);
    bool regular = llt_.info() == Eigen::Success;
    if (regular) {
      work_.setIdentity(m, m);
      llt_.matrixL().solveInPlace(work_);
      regular = work_.squaredNorm() * cutoff_ < 1.0;
    }
    if (regular) {
      if (l > 0.0) {
        gram_.diagonal().array() += l;
        llt_.compute(gram_);
      }
    } else {
      eigen_.compute(gram_);
      solve_ = Solve::rows_eigen;
    }
    return;
  }
  // more rows than joints: the column space, sqrt(S) (sqrt(S) J^T J sqrt(S) + l I)^-1 sqrt(S) J^T v
  root_ = s.cwiseSqrt();
  scaled_.noalias() = Jw * root_.asDiagonal();
  gram_.noalias() = scaled_.transpose() * scaled_;
  if (!pseudo) {
    gram_.diagonal().array() += l;
    llt_.compute(gram_);
    solve_ = Solve::columns_cholesky;
  } else {
    eigen_.compute(gram_);
    cutoff_ = std::max(p.rcond * p.rcond, kEigenFloor) *
              std::max(eigen_.eigenvalues().maxCoeff(), 0.0);
    solve_ = Solve::columns_eigen;
  }
}

void Method::apply(const Eigen::Ref<const RowMatrix>& Jw, const Eigen::Ref<const Vector>& v,
                   Eigen::Ref<Vector> out) {
  const double l = damping_;
  switch (solve_) {
    case Solve::none:
      out.setZero();
      return;
    case Solve::rows_cholesky:
      sol_ = v;
      llt_.solveInPlace(sol_);
      out.noalias() = scaled_.transpose() * sol_;
      return;
    case Solve::rows_eigen: {
      const Vector& values = eigen_.eigenvalues();
      const Eigen::MatrixXd& U = eigen_.eigenvectors();
      sol_.setZero(Jw.rows());
      for (Index c = 0; c < Jw.rows(); ++c)
        if (values[c] > cutoff_) sol_ += (U.col(c).dot(v) / (values[c] + l)) * U.col(c);
      out.noalias() = scaled_.transpose() * sol_;
      return;
    }
    case Solve::columns_cholesky:
      sol_.noalias() = scaled_.transpose() * v;
      llt_.solveInPlace(sol_);
      out = root_.cwiseProduct(sol_);
      return;
    case Solve::columns_eigen: {
      rhs_.noalias() = scaled_.transpose() * v;
      sol_.setZero(Jw.cols());
      for (Index c = 0; c < Jw.cols(); ++c) {
        const double value = eigen_.eigenvalues()[c];
        if (value > cutoff_)
          sol_ += (eigen_.eigenvectors().col(c).dot(rhs_) / (value + l)) *
                  eigen_.eigenvectors().col(c);
      }
      out = root_.cwiseProduct(sol_);
      return;
    }
  }
}

void Method::feedback(const Eigen::Ref<const RowMatrix>& Jw, const Eigen::Ref<const Vector>& ew,
                      const Eigen::Ref<const Vector>& k, const MethodStep& step,
                      Eigen::Ref<Vector> out) {
  v_.noalias() = step.gain * k.cwiseProduct(ew);
  if (p.family == Family::least_squares) {
    solve(Jw, v_, step.s, step.damping, p.mu == 0.0, out);
  } else if (p.damped_feedback) {
    solve(Jw, v_, step.alpha, step.damping, false, out);
  } else {
    out.noalias() = Jw.transpose() * v_;
    out.array() *= step.s.array();
  }
}

void Method::feedforward(const Eigen::Ref<const RowMatrix>& Jw,
                         const Eigen::Ref<const Vector>& ffw, const MethodStep& step,
                         Eigen::Ref<Vector> out) {
  if (p.family == Family::least_squares) {
    solve(Jw, ffw, step.s, step.damping, p.mu == 0.0, out);
  } else if (p.damped_feedback) {
    solve(Jw, ffw, step.alpha, step.damping, false, out);
  } else if (p.damped_feedforward) {  // (on the unit columns, JT's too)
    solve(Jw, ffw, step.alpha, p.mu * p.mu, false, out);
  } else {
    out.noalias() = Jw.transpose() * ffw;
    out.array() *= step.s.array();
  }
}

void Method::both(const Eigen::Ref<const RowMatrix>& Jw, const Eigen::Ref<const Vector>& ew,
                  const Eigen::Ref<const Vector>& k, const Eigen::Ref<const Vector>& ffw,
                  const MethodStep& step, Eigen::Ref<Vector> fb, Eigen::Ref<Vector> ff) {
  const bool least_squares = p.family == Family::least_squares;
  if (!least_squares && !p.damped_feedback) {  // (no solve in the feedback: nothing to share)
    feedback(Jw, ew, k, step, fb);
    feedforward(Jw, ffw, step, ff);
    return;
  }
  factor(Jw, least_squares ? step.s : step.alpha, step.damping, least_squares && p.mu == 0.0);
  v_.noalias() = step.gain * k.cwiseProduct(ew);
  apply(Jw, v_, fb);
  apply(Jw, ffw, ff);
}

}  // namespace sjt

// -- Python entries: the mapping as a matrix and SJT's scaling factors (analysis, tests)
#include <nanobind/eigen/dense.h>

#include "registry.hpp"

namespace sjt {

namespace {

// M(J) at zero error (the least damping) with unit gains: the method's matrix
RowMatrix mapping_matrix(const MethodParameters& p, const RowMatrix& Jw) {
  if (!Jw.allFinite()) fail("J contains NaN or inf");
  const Index m = Jw.rows(), n = Jw.cols();
  Method method;
  method.p = p;
  method.p.auto_gain = false;
  MethodStep step;
  const Vector zero = Vector::Zero(m), ones = Vector::Ones(m);
  method.prepare(Jw, zero, ones, m, 1.0, step);
  RowMatrix M(n, m);
  Vector column(n), unit(m);
  for (Index i = 0; i < m; ++i) {
    unit.setZero();
    unit[i] = 1.0;
    if (p.family == Family::transpose && !p.damped_feedback)
      method.feedback(Jw, unit, ones, step, column);
    else
      method.feedforward(Jw, unit, step, column);
    M.col(i) = column;
  }
  return M;
}

Vector scaling_factors(const MethodParameters& p, const RowMatrix& Jw) {
  Method method;
  method.p = p;
  method.p.auto_gain = false;
  MethodStep step;
  const Index m = Jw.rows();
  method.prepare(Jw, Vector::Zero(m), Vector::Ones(m), m, 1.0, step);
  return step.alpha;
}

}  // namespace

void register_method(nb::module_& m) {
  m.def("mapping_matrix", &mapping_matrix, nb::arg("parameters"), nb::arg("J"),
        "mapping_matrix(parameters, J) -> (n, m) array: the method's M(J) at its least damping "
        "(zero error), from the compiled mapping applied to the identity's columns.");
  m.def("scaling_factors", &scaling_factors, nb::arg("parameters"), nb::arg("J"),
        "scaling_factors(parameters, J) -> (n,) array: SJT's alpha_i = 1 / max(|J_i|^2, l^2) "
        "(eq. 18), 0 for columns below column_tol.");
}

}  // namespace sjt
