// The set-point search of solve() (sjt_pin/ik.py): Levenberg-Marquardt iterations on SJT's
// normalised columns within the joint limits, its parameters and state named fields of one
// object per search. search.cpp runs an iteration (search_binding.cpp: its Python side);
// search_pose.cpp runs every iteration of a start on one pose task in one call, and the restart
// table's starts.
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <vector>

#include "array.hpp"

namespace sjt {

// What an iteration reports (exported by name: CONTINUE, CONVERGED, SEARCH_STALLED)
enum SearchStatus : int { kContinue = 0, kConverged = 1, kSearchStalled = 2 };

// The state of one start: the best point so far (its error f = |W e|^2 / 2, |e|^2 over the
// target rows), the damping's factor nu, and the stall tests' counters.
struct SearchState {
  double f = 0.0, e_sq = 0.0, nu = 1.0, best = 0.0, held_best = 0.0;
  long iterations = 0, stale = 0, held_stale = 0;
  bool rejected = false;  // a trial of this start has been rejected
  bool quick = true;      // the quick stall test is on
};

class SetPointSearch {
 public:
  // rows: m = sqrt_weight's length (the stack's square-root row weights), n = mask's (1 for
  // the joints the search moves), nq coordinates; the position limits of c joints (their q and
  // v indices, lower and upper bounds); the method's column tolerance and, for SJT (scaled),
  // its floor length (m) under the column norms; identity_rows = n when the rows end with a
  // posture task's identity rows (solved as diagonal plus low rank), else 0.
  SetPointSearch(nb::handle sqrt_weight, nb::handle mask, Index nq, nb::handle limit_q,
                 nb::handle limit_v, nb::handle lower, nb::handle upper, double damping,
                 double column_tol, double length, bool scaled, Index identity_rows);

  // -- fixed for the search
  const Index m, n, nq;
  const double damping, column_tol, length;
  const bool scaled;
  const Index identity_rows;

  // -- the options of a solve (ik.py's constants): |e| below tol over the first error_rows
  // rows succeeds; no joint moves more than max_step (rad, m) in one iteration; a start has
  // stalled when its best f has not fallen below `progress` times itself for stale_iters
  // iterations (and, with the quick test, below held_progress times itself for held_iters
  // iterations while a joint is held at a limit or after a rejected trial); nu_start: nu at
  // a start
  double tol = 1e-6, max_step = 2.0, progress = 0.99, held_progress = 0.5, nu_start = 1.0;
  long error_rows = 0, stale_iters = 6, held_iters = 4;

  SearchState state;

  // A new start: the state reset (quick: with the quick stall test)
  void start(bool quick);
  // One iteration at the trial point (J row-major m x n, e (m), q (nq)), read before anything
  // is written: accepted or rejected, the stall tests, and the next step (into step()) from
  // the current point; returns a SearchStatus.
  int iterate(const double* J, const double* e, const double* q);

  // the current (best) point and the next step from it
  RowMatrix& J() { return J_; }
  Vector& e() { return e_; }
  Vector& q() { return q_; }
  Vector& step() { return step_; }

 private:
  Vector sqrt_weight_, mask_;
  std::vector<Index> limit_q_, limit_v_;
  Vector lower_, upper_;
  RowMatrix J_;
  Vector e_, q_, step_;
  // scratch: the weighted rows, the columns' norms and scales, the joints still free and the fixed
  // ones' displacements, the right-hand side; the factored normal matrices
  RowMatrix Jw_, scaled_;
  Vector alpha_, norms_, root_, fixed_, v_, rhs_, x_, diagonal_, t_;
  std::vector<char> free_;
  Eigen::MatrixXd normal_;
  Eigen::LLT<Eigen::MatrixXd> llt_;

  void limited_step();
  void damped_solve(double mu2);
  void llt_solve(const double* rhs, double* out);
  bool clamp();
  bool held() const;
  Index woodbury_rows() const;
};

}  // namespace sjt
