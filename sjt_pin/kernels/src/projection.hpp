// The constraint stage's projection: the feasible joint velocity nearest the method's, in the
// method's own metric.
//
//     min  1/2 (x - xb)^T diag(lam) (x - xb) + 1/2 |B (x - xb)|^2
//     s.t. lo <= x <= hi,   A x <= b,   C x = d
//
// lam > 0 per joint (inf: the joint is held at xb, clipped into its box), B (r x n) the
// low-rank part of the metric (r is a task's rows), A (k x n) general rows (collision dampers,
// a user's limits), C (c x n) equalities (the task motion of higher priority levels). The
// metric is diagonal plus low rank, so the problem is solved on its dual, whose size is
// r + c + (active rows), not n: for y = (lambda, eta, nu) the primal point is
// x(y) = clip(xb - lam^-1 (B^T lambda + C^T eta + A_W^T nu), lo, hi), separable per joint,
// and the dual function is concave and piecewise quadratic. Newton steps on it with an exact
// line search along the piecewise-linear derivative (each joint's clip is a breakpoint)
// converge in a few steps whatever the number of joints at a bound, and exactly once the set
// of clipped joints is right (semismooth Newton; Hintermueller, Ito and Kunisch 2002). The rows
// A x <= b enter through an active set on their multipliers nu >= 0 (the most violated row
// joins as an equality, a row whose multiplier turns negative leaves; Goldfarb and Idnani's
// dual strategy), so a step with no broken row costs no row at all. Equalities and active rows
// carry a ridge of 1e-12 of their own scale (rows that repeat or contradict each other leave a
// bounded multiplier); where no velocity within the box meets every row, the result breaks the
// rows by the least the ridge allows, within the box.
#pragma once

#include <Eigen/Dense>
#include <vector>

#include "array.hpp"

namespace sjt {

struct ProjectionReport {
  int iterations = 0;    // Newton steps in all
  int rows_active = 0;   // rows of A in the final working set
  bool converged = true; // the dual gradient below tolerance within the iteration budget
};

class Projection {
 public:
  Projection();  // (its decompositions computed once: see Method's constructor)

  // Solve; x is written (n). B, C, A may have zero rows. warm: start from the last dual point
  // where the problem has the same shape.
  ProjectionReport solve(const Eigen::Ref<const Vector>& xb, const Eigen::Ref<const Vector>& lam,
                         const Eigen::Ref<const RowMatrix>& B,
                         const Eigen::Ref<const Vector>& lo, const Eigen::Ref<const Vector>& hi,
                         const Eigen::Ref<const RowMatrix>& A, const Eigen::Ref<const Vector>& b,
                         const Eigen::Ref<const RowMatrix>& C, const Eigen::Ref<const Vector>& d,
                         Eigen::Ref<Vector> x, bool warm = false);

  // which rows of A were active (in the working set) at the last solve
  const std::vector<int>& active_rows() const { return working_; }

  // The dual point of the task rows and equalities (r + c; the working rows' multipliers
  // start anew), the working rows and the shape (n, r, c) a warm solve starts from (copies
  // carry them: a warm solve's result depends on them by rounding); n < 0: none (cold).
  struct WarmState {
    Vector y;
    std::vector<int> working;
    Index n = -1, r = -1, c = -1;
  };
  WarmState warm_state() const;
  void set_warm_state(const WarmState& state);
  void forget() { last_n_ = -1; }  // the next warm solve starts cold

  static constexpr int kInnerIterations = 60;
  static constexpr double kTolerance = 1e-14;
  static constexpr double kRidge = 1e-12;
  // a row broken by more than this share of its scale (|b| + |A_i| |x|) joins the working set
  static constexpr double kRowTolerance = 1e-13;

 private:
  void polish(const Eigen::Ref<const RowMatrix>& C, const Eigen::Ref<const Vector>& d,
              const Eigen::Ref<const RowMatrix>& A, const Eigen::Ref<const Vector>& b,
              const Eigen::Ref<const Vector>& lo, const Eigen::Ref<const Vector>& hi);
  int inner(const Eigen::Ref<const Vector>& xb, const Eigen::Ref<const Vector>& lo,
            const Eigen::Ref<const Vector>& hi, Index m, double scale);

  Vector inv_, z_, gx_, grad_, step_, w_, gs_, off_, ridge_, y_, y_saved_, residual_;
  RowMatrix G_, rows_;
  Eigen::CompleteOrthogonalDecomposition<Eigen::MatrixXd> cod_;
  Eigen::MatrixXd M_;
  Eigen::LLT<Eigen::MatrixXd> llt_;
  std::vector<int> working_;
  std::vector<std::pair<double, int>> events_;
  Index last_n_ = -1, last_r_ = -1, last_c_ = -1;
};

}  // namespace sjt
