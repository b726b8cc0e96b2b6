// One CLIK step after the tasks: the method on the stacked rows (level by level: a lower priority
// level acts in the null space of the higher ones), the saddle escape's velocity, each joint's
// box from the limits, a user's bounds and general rows, and the projection that keeps the
// method's step where it is feasible and returns the feasible velocity nearest it in the
// method's metric where it is not. Its state (the last commanded velocity and acceleration,
// the escape, the stall count) is named fields that copies carry whole.
#pragma once

#include <vector>

#include "array.hpp"
#include "bounds.hpp"
#include "method.hpp"
#include "projection.hpp"

namespace sjt {

// A block of rows of one priority level: rows [begin, end) of the stacked J; `identity`: a
// posture task's rows (J = I on the moving joints), whose velocity is K w (q_ref - q).
struct Level {
  Index begin = 0, end = 0;
  bool identity = false;
  Index targets = 0;  // leading rows of tasks that take targets (their error is reported)
};

// status bits of a step
enum Status : int {
  kNonFinite = 1,    // the error or the feed-forward is not finite: nothing was computed
  kStalled = 2,      // a stall the escape looks at (first stalled step, or a window's end)
  kConstrained = 4,  // the stage changed the method's step
  kConflict = 8,     // a smoothness limit yielded to a hard one
  kRowsBroken = 16,  // no velocity within the hard box meets every row (the least breach)
  kUnconverged = 32, // the projection ran out of iterations (its last point, within the box)
};

class Controller {
 public:
  Controller(const MethodParameters& method, Index rows, Index nv, Index nq, double dt,
             const Vector& sqrt_weight, const Vector& gains, const Vector& moving,
             Index error_rows, const std::vector<Level>& levels, const BoundsConfig& bounds,
             double stall_ratio, double stall_floor, const Vector& rank_scale);

  // One step: J (m x nv), e (m), ff (m) or none, q (nq); matrix: a user method's M (nv x r0,
  // row-major, r0 the first level's rows) mapping the first level instead of the built-in
  // method; user bounds (nv), rows A (k x nv), b (k), the rows' room (k; A d <= room for
  // a displacement d, NaN: none) or null, what the rows need (k; NaN: b; below b: the
  // row is given up, kept only within the acceleration and jerk limits, never yielding
  // them) or null, and which rows' bounds are their limit's damper of their room (k; 0: a
  // row the stage braked, whose bound says nothing of the room) or null (all of them).
  // Writes the displacement q_dot dt into `step` (nv); returns the status bits.
  int run(const Eigen::Ref<const RowMatrix>& J, const Eigen::Ref<const Vector>& e,
          const double* ff, const double* q, Eigen::Ref<Vector> step, const double* matrix,
          const double* user_lo, const double* user_hi,
          const Eigen::Ref<const RowMatrix>& A, const Eigen::Ref<const Vector>& b,
          const double* room = nullptr, const double* needs = nullptr,
          const double* dampers = nullptr);

  // A user method's matrix, before run(): the first level's weighted rows of J (m x nv), as
  // the step weighs them, into `rows` (r0 x nv, row-major: the rows the method is given).
  void first_rows(const Eigen::Ref<const RowMatrix>& J, const Eigen::Ref<const Vector>& e,
                  double* rows);
  // its M of Fortran order (numpy's J.T), copied row-major for run()'s products (nv x r0)
  RowMatrix user_matrix;

  void set_dt(double dt) { dt_ = dt; }
  double dt() const { return dt_; }
  void set_gains(const Vector& gains, bool auto_gain, double factor);
  void set_speed(const Vector& speed);
  // the first rows of the first level's pose errors (log6 blocks of 6 target rows, see run)
  void set_log6_rows(const Eigen::Matrix<int64_t, Eigen::Dynamic, 1>& rows);
  void reset();

  // -- parameters
  Method method;
  Index m, nv, nq, error_rows;
  Vector sqrt_weight, gains, moving;
  // per row, 1 over its task's largest sqrt_weight (fade_posture: each task's rows on one scale)
  Vector rank_scale;
  std::vector<Level> levels;
  BoundsConfig bounds;
  double stall_ratio, stall_floor;

  // -- state (copies carry it): the last commanded velocity and acceleration, the escape
  Vector dq, ddq, escape_velocity;
  bool escaping = false;
  double given_gain = 1.0;  // K of a user method's last feedback (its fb / K is the displacement)
  double stall_run = -1.0, stall_wait = 1e300;
  // the saddle escape's curvature test found a minimum where the arm stalls (no saddle, no
  // settling step worth taking): until the stall ends the first level's feedback is the
  // method's projected onto the first rest_rank columns of rest_keep (nv x rest_rank,
  // row-major, orthonormal: the directions other than the minimum's flat ones)
  bool resting = false;
  // settle's start from rest: |e_w| when the last one began (inf: none), and whether the
  // arm is still in it
  double start_error = 1e300;
  bool start_run = false;
  // the least |e|^2 of the steps' targets (e_sq) since the target last moved (inf: none):
  // settle's check that a step along the line toward the goal's velocity still gains
  double least_e_sq = 1e300;
  double least_age = 0.0;  // s since least_e_sq was last lowered
  // a row pushed the arm from rest (its bound below zero: inside the margin) and the arm's
  // motion still raises the error: least_e_sq follows the error meanwhile
  bool pushed = false;
  // the factor on range_goal's damping where rows with room bind it (raise_damping), |e|
  // where it last changed or a start from rest began (1e300: neither since the target moved),
  // and how many times it was raised since (forget_damping: none)
  double damped_error = 1e300;
  double goal_damping = 1.0;
  int damping_raises = 0;
  Vector rest_keep;
  Index rest_rank = 0;
  // the first level's pose errors take their exact rows (exact_rows; set after `still`
  // consecutive steps at rest at a position range short of the target, cleared near it or
  // when the target jumps)
  bool exact = false;
  double still = 0.0;
  Vector expected;  // the first level's weighted target error the next step expects (exact)
  // the first level's nearest feasible velocity (without acceleration limits) starts from the
  // last step's dual point: along a path the set of joints at a bound rarely changes, and one
  // Newton step then solves it (Kinova's 1 cm circle beyond its speed limits: 6.6 Newton
  // steps a step cold, 2.5 warm; random full-range reaches on UR5, Panda, iiwa and xArm6:
  // 1.4-4.0 cold, 0.6-1.7 warm, the same results to rounding; the collision bench's scenes:
  // 0.37-0.54 of the cold steps, an arm sliding along an obstacle amplifying the rounding to
  // 1e-5 rad on the way, the same rest)
  Projection nearest;

  // -- the last step, for StepInfo
  MethodStep top;                 // level 0's analysis (alpha, gain, loop bound, ...)
  double e_sq = 0.0, ff_sq = 0.0, regular = 0.0, task_scale = 1.0;
  // the share of a posture's self-motion the first level's rank leaves it (fade_posture)
  double posture_share = 1.0;
  Vector desired, fb, ff, velocity;  // the method's velocity, its two parts, and the result
  Vector desired_top;                // the first level's own velocity (with the escape's)
  // the velocity whose bounds and rows StepInfo names as holding the arm: the result, or
  // where the arm rests short of a step worth making (sufficient_decrease), that step
  Vector holding;
  JointBox box;
  std::vector<int> rows_active;
  ProjectionReport report;
  bool kept = true;
  bool exact_step = false;  // this step's pose errors took their exact rows
  // the last step's J0 dq and whether there is one (measured_bend): state copies carry
  std::tuple<bool, Vector> curvature_memory() const { return {bent_ready_, bent_}; }
  void set_curvature_memory(bool ready, const Vector& bent) {
    bent_ready_ = ready;
    bent_ = bent;
  }

 private:
  static constexpr double kBoundTol = 1e-12;  // rad/s: a velocity this close to a bound is on it
  // 1/s: a projected step that lowers the linearised 1/2 |e_w|^2 by less than this share of
  // |e_w|^2 per second is no motion worth making, and the arm rests (sufficient_decrease).
  // Measured against obstacles the arm cannot pass (Panda, xArm7; tests/test_collision_rest.py):
  // the projection's answer there lowered it by 3e-7 to 2.2e-5 of itself per second while the
  // elbow slid at 3e-3 to 8e-2 rad/s and the true error stayed or grew (Panda's seed 7 by 5e-4
  // per second); any step that makes progress worth the name does far more (the method's own
  // gain is 1 to 100 per second). xArm7 behind a box under jerk limits (blocked seed 1, SJT)
  // slid along it at 0.1 rad/s for good, lowering |e_w|^2 by 4.7e-4 of itself per second (its
  // hand 0.2 mm closer in 3.5 s, its orientation further off): 1e-4 let it, 1e-3 rests it at
  // 1.8 s and leaves random reaches and the jerk grid as they were (UR10's SJT one miss fewer).
  // Not while the saddle escape adds a velocity (its own test found the error lower along it,
  // and it yields if the error grows)
  static constexpr double kRestRate = 1e-3;
  // a growth of |e|^2 by this factor in one step is a target that moved (least_e_sq forgets)
  static constexpr double kRecord = 1.1025;
  // a row's motion (m/s for a collision pair's) below minus this is the arm moving away along
  // it (run: the error's record after a push)
  static constexpr double kPushed = 1e-9;
  // the exact rows of a pose error (run, exact_rows): taken after this many consecutive steps
  // held by a position range short of the target, lowering 1/2 |e_w|^2 by less than kRestRate
  // of it a second, with |e_w| above kExactFrom times the converged floor; given back once
  // |e_w| is below kExactTo times it (1e-4 of the tasks' length: the two models' rows then
  // agree to that share) or the target jumps (kJump, keeps_exact)
  static constexpr double kStillSteps = 10.0;
  static constexpr double kExactFrom = 1e3, kExactTo = 1e2, kJump = 0.1;
  static constexpr double kRangeTol = 1e-6;  // rad, m: a joint this close to its range is on it

  // the levels below the first (lower_levels.cpp)
  void lower_levels(const double* ffw, const double* q);
  double fade_posture(const double* q);
  void extend_basis(const RowMatrix* rows, Index begin, Index count);
  void null_project(Vector& v);
  double lower_metric();
  ProjectionReport lower_nearest(const Eigen::Ref<const RowMatrix>& J0, const Vector& base,
                                 const Vector& target, const Eigen::Ref<const RowMatrix>& A,
                                 const Eigen::Ref<const Vector>& b, const Vector& lo,
                                 const Vector& hi, Vector& out);
  bool lower_goal(const Eigen::Ref<const RowMatrix>& J0, const double* q, double K,
                  const Eigen::Ref<const RowMatrix>& A, bool rows);
  // the first level and the stage: the nearest feasible step (feasible_step.cpp), where the
  // arm rests (least_squares_rest.cpp, settle.cpp), a user's method (controller.cpp)
  bool feasible(const Vector& x, const Eigen::Ref<const RowMatrix>& A,
                const Eigen::Ref<const Vector>& b, const Vector& lo, const Vector& hi) const;
  void held_by_ranges(const Vector& d, const Vector& lo, const Vector& hi);
  void range_box(const double* q, Vector& lo, Vector& hi) const;
  void map_matrix(const Eigen::Ref<const RowMatrix>& J0, const double* matrix, bool with_ff);
  void sufficient_decrease(const Eigen::Ref<const RowMatrix>& J0,
                           const Eigen::Ref<const RowMatrix>& A,
                           const Eigen::Ref<const Vector>& b,
                           const Eigen::Ref<const RowMatrix>& H,
                           const Eigen::Ref<const Vector>& hd, double ball);
  void cauchy_point(const Eigen::Ref<const RowMatrix>& J0, const Vector& a, const Vector& lo,
                    const Vector& hi, double ball);
  double trusted_share(const Eigen::Ref<const RowMatrix>& J0, double along, double jj,
                       double xx);
  double measured_bend(const Eigen::Ref<const RowMatrix>& J0);
  bool range_goal(const Eigen::Ref<const RowMatrix>& J0, const double* q, double K, bool user,
                  const Eigen::Ref<const RowMatrix>& A, const Eigen::Ref<const Vector>& b,
                  const double* room, const double* dampers);
  bool restart_from_rest();
  bool raise_damping();
  void follow_damping(bool target_moved);
  void forget_damping();
  bool at_rest() const;
  bool fit_within_box(const Eigen::Ref<const RowMatrix>& J0, const Eigen::Ref<const RowMatrix>& A,
                      const Eigen::Ref<const Vector>& b);
  void rest_along_flat();
  void settle(const Eigen::Ref<const RowMatrix>& J0, const double* q,
              const Eigen::Ref<const RowMatrix>& A, const Eigen::Ref<const Vector>& b,
              const double* user_lo, const double* user_hi);
  void keep_direction(const Eigen::Ref<const RowMatrix>& J0, const Eigen::Ref<const RowMatrix>& A,
                      const Eigen::Ref<const Vector>& b, const Vector& lo, const Vector& hi,
                      const Eigen::Ref<const RowMatrix>& H, const Eigen::Ref<const Vector>& hd);
  // (hold: the first level's held rows as equalities; in the hard box)
  void project(const Eigen::Ref<const RowMatrix>& A, const Eigen::Ref<const Vector>& b,
               const Vector& box_lo, const Vector& box_hi, bool hold);
  bool rows_hold(const Eigen::Ref<const RowMatrix>& A, const Eigen::Ref<const Vector>& b) const;
  bool rows_hold_within(double s, const Eigen::Ref<const RowMatrix>& A,
                        const Eigen::Ref<const Vector>& b);
  bool hold_rows(const Eigen::Ref<const RowMatrix>& A, const Eigen::Ref<const Vector>& b);
  bool held_kept(const Vector& x);
  void yield_smoothness(const Eigen::Ref<const RowMatrix>& A, const Eigen::Ref<const Vector>& b);
  void within_hard_box(const Eigen::Ref<const RowMatrix>& A, const Eigen::Ref<const Vector>& b);

  double dt_;
  RowMatrix Jw_, Jhat_, Bnone_, B_, coupling_;
  // lower_levels: the orthonormal basis of the rows above a level (its first rank_ columns),
  // the largest of those rows' norms, a level's task velocity
  Eigen::MatrixXd basis_;
  Eigen::MatrixXd loop_;  // map_matrix: J0 M, and the gain times the first level's error
  Vector kew_;
  Index rank_ = 0;
  double top_norm_ = 0.0;
  bool has_posture_ = false;
  RowMatrix lock_rows_;
  Eigen::MatrixXd lock_gram_, lock_shift_;
  Eigen::LLT<Eigen::MatrixXd> lock_llt_;
  Vector lock_free_;
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> lock_eig_;
  Vector coef_, level_t_;
  Vector ew_, ffw_, fb0_, ff0_, x0_, xa_, tstar_, gt_, direction_, tmp_, tmp2_, lam_low_;
  // project(): the box with unbounded joints capped; the task velocity that removes level 0's
  // error in a step (e_w / dt, and the feed-forward); J0^T of it, the error's steepest
  // descent; the Cauchy point and its path's state
  Vector plo_, phi_, wanted_, descent_, cauchy_, free_, jd_, res_, rest_, rest_coef_;
  bool rested_ = false;
  // lower_nearest's task rows, their posture's diagonal, its anchor and Woodbury solve
  RowMatrix low_B_;
  Vector low_p_, low_h_, low_r_, low_d_, low_dh_, low_dinv_, low_c_, anchor_;
  // lower_goal: the top level's displacement, the lower levels' one asked, its box and result
  Vector lgoal_base_, lgoal_target_, lgoal_lo_, lgoal_hi_, lgoal_;
  // measured_bend: J0 dq at the end of the last step (its curvature, measured at this one),
  // whether there is one, and whether this step's first level was projected
  Vector bent_, bent_now_;
  // the first level's pose errors: their first rows, and G = Jlog6 and G J (exact_rows.cpp)
  std::vector<Index> log6_rows_;
  RowMatrix jlog6_, exact6_;
  void exact_rows(const Eigen::Ref<const RowMatrix>& J, const Eigen::Ref<const Vector>& e,
                  const double* ff_in, Eigen::Ref<RowMatrix> out, Index first);
  void watch_rest(int status, const double* q, const Eigen::Ref<const Vector>& step);
  bool keeps_exact(const Eigen::Ref<const Vector>& e);
  bool bent_ready_ = false, projected_ = false;
  double bend_ = -1.0;  // this step's measured_bend (-1: not measured yet)
  bool lower_replaced_ = false;  // lower_goal replaced the lower levels' feedback this step
  Vector method_desired_;        // the method's velocity before it (StepInfo compares with it)
  Eigen::MatrixXd low_gram_;
  Eigen::LLT<Eigen::MatrixXd> low_llt_;
  std::vector<std::pair<double, Index>> breaks_;  // the Cauchy path's breakpoints
  Vector wide_lo_, wide_hi_, delta_, aim_, bk_;
  Vector held_, held_res_;  // hold_rows: the held rows' motion, their residual
  // range_goal: the least-squares displacement (its Gram matrix and factor), its box, result
  RowMatrix goal_model_;  // J0 and the measured curvature's row
  Eigen::MatrixXd goal_gram_;
  Eigen::LLT<Eigen::MatrixXd> goal_llt_;
  Vector goal_xb_, goal_lam_, goal_lo_, goal_hi_, goal_, goal_y_, goal_e_, goal_d_, goal_room_,
      method_top_;
  JointBox rest_box_;      // settle: the box of braking to rest
  // fit_within_box: its box about the velocity, J0 (desired - v), the velocity it found
  Vector fit_lo_, fit_hi_, fit_a_, fit_v_;
  Vector goal_desired_;  // the goal's velocity where the step went along the line toward it
  bool synced_ = false;
  bool goal_rows_ = false;  // a row's room binds range_goal's displacement (settle applies)
  bool goal_dampers_ = false;  // ... and one of those rows is a damper (b / K caps it)
  bool replaced_ = false;  // range_goal replaced the first level's feedback this step
  Method lower_;
  MethodStep lower_step_;
  Projection projection_;
};

}  // namespace sjt
