// The CLIK mappings M(J) of one step (the paper's eq. 8, 10 and 21, and their damped forms), and
// for the constraint stage each one's metric.
//
//   SJT, JT, damped feedback   q_dot = S J_w^T (J_w S J_w^T + l I)^-1 v
//   SJT, JT, transpose (eq.21) q_dot = S J_w^T K e_w   (+ the damped feed-forward)
//   DLS, JP (+ Levenberg-M.)   q_dot = J_w^T (J_w J_w^T + l I)^-1 v
//
// with S = D = diag(alpha_i) for SJT (alpha_i = 1 / max(|J_w,i|^2, length^2), eq. 18), S = I
// for JT, v = K e_w + x_dot_d,w the weighted task velocity, l the damping (mu^2 plus the
// Levenberg-Marquardt term that grows with the error).
//
// The stage's metric without acceleration limits, for SJT's damped form and least squares, is
// the Hessian of the objective their step minimises, diag(lam) + J_w^T J_w (objective_rows).
// Otherwise (under acceleration limits, where the stage keeps the step's direction first, and
// for the transpose feedback) it is H = diag(lam) + mu_T J_w^T G J_w, in two parts:
// - G, a task-space metric in which the method's task motion t* = J_w q_dot* is K e_w itself:
//   G t* = K e_w (G = I + l (J S J^T)^-1 for the damped forms, (J S J^T)^-1 for the transpose
//   feedback, I for JP). Then the point of any convex feasible set nearest t* in G is a descent
//   direction of 1/2 |e_w|^2 whenever the set holds one: K e_w . p >= |p|^2_G;
// - lam, the method's own joint metric (l S^-1, S^-1 or l I): among the velocities with the
//   same task motion, the one nearest the method's step; mu_T puts the task first (a change of
//   the task motion costs 1e6 times a change of self-motion), so joints held at a bound leave
//   the task to the others wherever they can take it.
#pragma once

#include <Eigen/Dense>

#include "array.hpp"

namespace sjt {

enum class Family : int { transpose = 0, least_squares = 1 };

struct MethodParameters {
  Family family = Family::transpose;
  bool scaled = true;            // transpose family: SJT's D (false: JT)
  bool damped_feedback = true;   // transpose family: the feedback through the damped solve
  bool damped_feedforward = true;  // transpose family: the feed-forward through it
  double mu = 0.01;              // transpose family: mu of the damped solve (dimensionless,
                                 // on unit columns); least squares: DLS's lambda (task units; 0: JP)
  double column_tol = 1e-10;     // squared column norm below which a joint moves no task
  double length2 = 0.0;          // SJT's floor l^2 under the column norms (task units^2)
  double lm = 0.5;               // Levenberg-Marquardt weight (transpose: w; least squares: w L)
  double rcond = 1e-12;          // JP: singular values below rcond sigma_max count as zero
  bool auto_gain = true;         // K = c / (dt lambda_hat) at every step, else the rows' K
  double gain_factor = 1.0;      // c of the automatic gain
  static constexpr double kTaskFirst = 1e6;   // mu_T relative to the joint metric
};

// One level's mapping at one configuration: its factorisation, reused for every right-hand side.
struct MethodStep {
  Vector alpha;  // SJT's alpha_i (0 for JT / least squares); size n
  Vector s;      // column scale S (alpha or the mask)
  double gain = 1.0, loop_bound = 1.0, stall = 1.0, trace = 0.0, damping = 0.0;
  double e_sq = 0.0, ew_sq = 0.0, ff_sq = 0.0;
  Vector lam;  // the stage's joint metric (inf: a joint the level does not move)
};

class Method {
 public:
  MethodParameters p;

  // (each decomposition computed once on a 1 x 1 identity: Eigen leaves a decomposition's info
  // unset until its first compute, and moving an unset one - nanobind moves the Controller that
  // holds this - reads it: undefined behaviour, UBSan's invalid enum load)
  Method();

  // Analyse the weighted, masked rows Jw (m x n) at this step: scales, gain, damping, metric.
  // ew: the weighted error (m), error_rows: how many of the rows are the tasks' error (their
  // |e|^2 is reported), k: the rows' gains, dt: the period; gain: false where the caller sets
  // the gain and the loop bound itself (a user's matrix: both are 1 here then)
  void prepare(const Eigen::Ref<const RowMatrix>& Jw, const Eigen::Ref<const Vector>& ew,
               const Eigen::Ref<const Vector>& k, Index error_rows, double dt, MethodStep& out,
               bool gain = true);
  // The feedback q_dot (n) for the weighted error ew with gains k (K e_w), and the feed-forward
  // q_dot for the weighted task velocity ffw: after prepare() on the same rows.
  void feedback(const Eigen::Ref<const RowMatrix>& Jw, const Eigen::Ref<const Vector>& ew,
                const Eigen::Ref<const Vector>& k, const MethodStep& step, Eigen::Ref<Vector> out);
  void feedforward(const Eigen::Ref<const RowMatrix>& Jw, const Eigen::Ref<const Vector>& ffw,
                   const MethodStep& step, Eigen::Ref<Vector> out);
  // Both at once: where they map through the same matrix (least squares, the damped feedback)
  // one factorisation serves both (the feed-forward cost a second one)
  void both(const Eigen::Ref<const RowMatrix>& Jw, const Eigen::Ref<const Vector>& ew,
            const Eigen::Ref<const Vector>& k, const Eigen::Ref<const Vector>& ffw,
            const MethodStep& step, Eigen::Ref<Vector> fb, Eigen::Ref<Vector> ff);
  // The damped solve of the method's columns, S J_w^T (J_w S J_w^T + l I)^-1 v (least squares:
  // the pseudoinverse when l = 0): lower priority levels and the damped forms.
  void solve(const Eigen::Ref<const RowMatrix>& Jw, const Eigen::Ref<const Vector>& v,
             const Eigen::Ref<const Vector>& s, double l, bool pseudo, Eigen::Ref<Vector> out);
  // solve() in two halves: the decomposition of (Jw, s, l, pseudo), then its answer for a v
  // (as many v as wanted, on the same Jw, until the next factor())
  void factor(const Eigen::Ref<const RowMatrix>& Jw, const Eigen::Ref<const Vector>& s,
              double l, bool pseudo);
  void apply(const Eigen::Ref<const RowMatrix>& Jw, const Eigen::Ref<const Vector>& v,
             Eigen::Ref<Vector> out);

  // The stage's task part of the metric: B (m x n) with B^T B = mu_T J_w^T G' J_w, G' = G +
  // beta P^T G P, P = I - t t^T G / (t^T G t) the G-orthogonal projector off the task motion t
  // (beta > 0: a task motion off t's direction costs 1 + beta times more than one along it; see
  // the file's comment); G itself after the call in task_metric().
  // (G and mu_T are computed on the first call after forget(), or when the rows change in
  // number; the calls that follow reuse them)
  void metric(const Eigen::Ref<const RowMatrix>& Jw, const MethodStep& step,
              const Eigen::Ref<const Vector>& t, double beta, RowMatrix& B);
  void forget() { metric_ready_ = false; }
  // SJT's damped form and least squares: B = J_w, the task part of the Hessian of the objective
  // their step minimises, 1/2 |J_w q_dot - v|^2 + 1/2 q_dot^T diag(lam) q_dot (v = K e_w and
  // the feed-forward; lam = l D^-1, or l I), so that the stage's metric diag(lam) + B^T B is
  // that Hessian; true. Otherwise false, B untouched (the stage takes metric()): the transpose
  // feedback's objective 1/2 q_dot^T diag(lam) q_dot - (K e_w)^T J_w q_dot has no task part,
  // and JT's damped step is not the minimiser of one with its joint metric (l |J_i|^2).
  bool objective_rows(const Eigen::Ref<const RowMatrix>& Jw, RowMatrix& B) const;
  const Eigen::MatrixXd& task_metric() const { return metric_; }

  // the largest eigenvalue of the symmetric part of the square A, (A + A^T) / 2: at least the
  // real part of each eigenvalue of A (Bendixson), lambda_max itself where A is symmetric
  double symmetric_top(const Eigen::MatrixXd& A);

  // an upper bound of lambda_max of the PSD A: (tr A^(2^(P+1)))^(1/2^(P+1)), P = 2
  double loop_bound(const Eigen::Ref<const Eigen::MatrixXd>& A);

 private:
  // which decomposition factor() left: none (no rows), Cholesky or eigen-decomposition of the
  // row space (m <= n) or of the column space
  enum class Solve { none, rows_cholesky, rows_eigen, columns_cholesky, columns_eigen };
  Solve solve_ = Solve::none;
  double damping_ = 0.0, cutoff_ = 0.0;
  Eigen::MatrixXd gram_, work_, work2_;
  Eigen::LLT<Eigen::MatrixXd> llt_;
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen_;
  Vector rhs_, sol_, v_, gt_, norms_, root_;
  RowMatrix scaled_;
  Eigen::MatrixXd metric_, directed_;
  Eigen::LLT<Eigen::MatrixXd> metric_llt_;
  double task_weight_ = 1.0;
  bool metric_ready_ = false;
};

}  // namespace sjt
