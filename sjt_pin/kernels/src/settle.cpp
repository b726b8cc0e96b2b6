// Settling against a row (controller.hpp): where range_goal's displacement is bound by a row's
// room, a velocity that makes too little progress brakes to rest, and an arm at rest starts.
#include "controller.hpp"

#include <algorithm>
#include <cmath>

namespace sjt {

namespace {

// settle: a motion whose first-order decrease of the error is below this share of
// |e_w| |J0 v| is one the model cannot tell from an increase (the pose error's log bends the
// map from J0 v to the error's rate by about |e_w| / 2 of |J0 v|). xArm7 behind an obstacle
// under acceleration and jerk limits (blocked seed 1, DLS) slid at 0.05 rad/s with its error
// growing by 2e-4 per second, where the model promised a decrease of 1e-3 of |e_w| |J0 v|;
// 3e-3 stopped xArm6's blocked seed 2 (SJT) at an error of 0.176 where 1e-3 lets it reach 0.107
constexpr double kAligned = 1e-3;
// settle's starts: the share of |e_w| a start must have gained since the last one, and the
// growth of |e_w| that forgets the last one (a target moved)
constexpr double kStartProgress = 0.01, kStartReset = 0.05;
// a step along the line toward the goal's velocity: the time (s) without a new least of
// |e|^2 beyond which it counts as gaining nothing
constexpr double kWindow = 0.2;
// range_goal's damping factor where rows with room bind it (raise_damping): its growth where
// the line failed, the most raises per target, and the fall of |e| (a share of it) after
// which it shrinks back (follow_damping)
constexpr double kDampingGrowth = 4.0, kDampedProgress = 0.01;
constexpr int kMostRaises = 8;

}  // namespace

// Where range_goal replaced the feedback and a row's room binds it, a velocity that lowers
// 1/2 |e_w|^2 by less than a resting arm does (kRestRate), or by less than the model can vouch
// for (kAligned), gives way to braking to rest, as a projected step does
// (sufficient_decrease): fully at that rate, not at all at twice it (both velocities keep the
// rows, and so does their blend; the progress counts the feed-forward's motion too: judging
// the feedback's share alone stopped UR3 while its target still moved). Each joint brakes
// toward its own share of the displacement, which bends the motion away from it; against an
// obstacle, whose rows' room is linearised anew each step, Panda's arm slid along it at
// 0.045 rad/s for seconds while lowering its error by 6e-7 of itself per second (blocked
// seed 11 under acceleration limits), where the displacement promised 30 times more. (Not
// where the ranges alone bind it: those rates also fall while the arm closes in on the
// constrained minimum, and it stopped 1e-4 short of stationarity on UR5, UR10 and Panda, and
// 3.5e-3 short of xArm7's final target in the stream of `bench accuracy`.)
// Under jerk limits an arm at rest starts anew before it is braked: each joint clipped alone
// into the sliver of a box the jerk limit leaves it moved the task sideways or back, the
// braking kept the arm at rest, and the next step was the same (UR10 48 mm above a box, a
// target behind it: it never moved). There the velocity within the same box nearest the
// feedback's task motion (fit_within_box) replaces the clipped one where it lowers the error
// faster, while every joint is slow (within the speed one step or one ramp of its jerk limit
// gives it). A new start needs the last one to have brought |e_w| down by kStartProgress of
// itself: starting again and again, arms at a table's margin wandered along it in their
// self-motion at 0.1-0.7 rad/s for good (UR10, xArm7, UR3; 4 of 22 runs of a survey).
// Without jerk limits the boxes are not slivers, and starts where a damper row binds the
// displacement (b / K: a step's worth along a collision pair's row, not the constrained
// minimum) kept arms at an obstacle sliding along it (TALOS's arm on the blocked bench: still
// moving at 8 s); where rooms alone bind it (a user's rows) they start there too: Panda (SJT)
// sent through a user's floors under acceleration limits alone never left its start, or
// rested 24 mm above them (all 4 runs, one per speed cap; with starts, 1 run 49 mm above
// them; with the line toward the goal's velocity in run, none).
void Controller::settle(const Eigen::Ref<const RowMatrix>& J0, const double* q,
                        const Eigen::Ref<const RowMatrix>& A, const Eigen::Ref<const Vector>& b,
                        const double* user_lo, const double* user_hi) {
  const Index targets = levels[0].targets;
  if (targets == 0) return;
  goal_y_.noalias() = J0 * velocity;
  const auto e = goal_e_.head(targets), moved = goal_y_.head(targets);
  // a resting arm's rate, and what the model cannot tell from none, for the motion in `moved`
  const auto rest_rate = [&] {
    return std::max(kRestRate * e.squaredNorm(), kAligned * e.norm() * moved.norm());
  };
  double rate = e.dot(moved);
  double rest = rest_rate();
  // Along the line toward the goal's velocity (run) the model's rate is checked against the
  // error measured: a step there gains nothing once |e|^2 has not reached a new least since
  // the target moved for kWindow. Beside a collision row the goal's model is not the error:
  // without this, xArm7 above a table still slid along it after 8 s in 4 of 6 runs (SJT and
  // DLS, acceleration limits alone or jerk limits 2,000 times them), and in an earlier form
  // of the line UR5 at 5 mm/s, its error growing by 3e-4 a second where the model promised a
  // decrease. (A bound on the error's rise above its least stopped arms short instead: theirs
  // rose 0.3-1 % on the way down to a user's floor, 5 % near a target through a ring.)
  // Where the window runs out while the arm moves, the goal's model was too bold: its damping
  // is raised (raise_damping) and the line goes on, judged anew from here; it brakes once the
  // raises are spent (or at rest, where a start from rest is judged instead)
  if (synced_ && least_age > kWindow) {
    if (!at_rest() && raise_damping()) {
      least_e_sq = e_sq;
      least_age = 0.0;
    } else {
      rate = std::min(rate, 0.0);
    }
  }
  // A step along the line from rest or slow moves little this period, less than a resting
  // arm would: it is judged by where it heads, the goal's own motion, while the error is at
  // its least (UR5 sent through a user's floors under jerk limits rested 3.5 cm along them
  // from its constrained minimum), or from rest above it (restart_from_rest). (goal_y_ is
  // scratch: `moved` is the step's motion again only where the step is judged on)
  if (synced_ && rate > 0.0 && rate < 2.0 * rest) {
    goal_y_.noalias() = J0 * desired;
    const bool heading = e.dot(moved) >= 2.0 * rest_rate();  // (down the error)
    if (heading && (e_sq <= least_e_sq || restart_from_rest())) return;
    goal_y_.noalias() = J0 * velocity;
  }
  // (a start: every joint within the speed one step or one jerk ramp gives it; without jerk
  // limits only where no damper row binds the displacement, which b / K bounds to a step's
  // worth along the row: there a start slid along the obstacle)
  bool slow = true;
  for (Index j = 0; j < nv; ++j) {
    const double acc = bounds.acceleration[j], jerk = bounds.jerk[j];
    slow = slow && (std::isfinite(jerk) || !goal_dampers_) &&
           std::abs(dq[j]) <= acc * (std::isfinite(jerk) ? std::max(dt_, acc / jerk) : dt_);
  }
  const double error = e.norm();
  if (!slow) start_run = false;
  if (error > (1.0 + kStartReset) * start_error) start_error = kInf;  // (the target moved)
  if (!(rate < 2.0 * rest)) return;
  // a new start only where the last one brought the error down by kStartProgress of itself
  const bool may_start = slow && (start_run || error < (1.0 - kStartProgress) * start_error);
  if (may_start && fit_within_box(J0, A, b)) {
    goal_y_.noalias() = J0 * fit_v_;  // (the fit's motion: not read again where not taken)
    const double fit_rate = e.dot(moved);
    if (fit_rate > rate) {
      if (!start_run) start_error = error;
      start_run = true;
      velocity = fit_v_;
      rate = fit_rate;
      rest = rest_rate();
      if (!(rate < 2.0 * rest)) return;
    }
  }
  rest_box_ = box;
  delta_.setZero(nv);
  joint_box(bounds, dt_, q, dq, delta_, ff, delta_, user_lo, user_hi, rest_box_);
  rest_ = ff.cwiseMax(rest_box_.lo).cwiseMin(rest_box_.hi);
  if (!feasible(rest_, A, b, rest_box_.lo, rest_box_.hi) || !held_kept(rest_)) return;
  const double w = std::clamp(rate / rest - 1.0, 0.0, 1.0);
  holding = velocity;  // (what StepInfo names as holding the arm: the motion not made)
  rested_ = true;
  velocity = w * velocity + (1.0 - w) * rest_;
}

// An arm at rest (at_rest) whose line heads down the error, above the error's record: the
// record starts anew here and the line goes on. Braked to rest above its record, an arm never
// started again: UR5 (SJT and DLS, jerk limits 500 times its acceleration limits), its hand
// started 2 mm inside a table's margin, was pushed out and braked, and rested at the margin
// 0.304 from its target, where the same solver without acceleration limits slides on to
// 0.2585, as it now does. A start that gained less than kDampedProgress of |e| since the last
// counts as a failed line: it raises the damping (judged by the window alone, such starts went
// on at the same damping, and 29 of 144 starts inside a table's margin rested 2.6-7.9 cm
// further from their targets: UR5, UR10, Kinova), and once the raises are spent the arm
// rests. True: it started.
bool Controller::restart_from_rest() {
  if (!at_rest()) return false;
  const double error = std::sqrt(e_sq);
  if (error < (1.0 - kDampedProgress) * damped_error) damped_error = error;
  else if (!raise_damping()) return false;
  least_e_sq = e_sq;
  least_age = 0.0;
  return true;
}

// Every joint within one step of its acceleration limit of rest (run's push; raise_damping's
// window: raised at rest too, the damping was spent there without motion, and UR5 above a
// table crept on by 1e-5 rad and less for 1.5 s before its bitwise rest).
bool Controller::at_rest() const {
  for (Index j = 0; j < nv; ++j)
    if (std::abs(dq[j]) > bounds.acceleration[j] * dt_) return false;
  return true;
}

// Levenberg-Marquardt's adaptive damping (Nocedal and Wright 2006, section 10.3) on range_goal's
// displacement where rows with room bind it: a line that failed (the error made no new least
// for kWindow, or a start from rest gained too little) raises the damping kDampingGrowth-fold,
// which shortens the displacement and turns it toward the gradient J0^T e_w, whose every share
// lowers the error by itself; follow_damping lowers it again once |e| has fallen
// kDampedProgress below where it was raised. Traced: UR10 (SJT, jerk limits 100 times its
// acceleration limits, started 2 mm inside a table's margin) slid along the table, its error
// rising where the light damping's Gauss-Newton displacement (at 0.01 of the gradient's
// direction, cosine) promised a fall, and the window braked it to rest at 0.2305; with the
// damping raised it slides on to its constrained minimum, 0.1519. At most kMostRaises raises
// per target (a row's push does not refund them: xArm7 sliding along a table dipped 0.04 mm
// into the margin at each rest, was pushed, and slid on for good). True: it raised.
bool Controller::raise_damping() {
  if (damping_raises >= kMostRaises) return false;
  ++damping_raises;
  goal_damping *= kDampingGrowth;
  damped_error = std::sqrt(e_sq);
  return true;
}

// After each step: a target that moved forgets the damping; the damping a failed line raised
// falls back once |e| has fallen kDampedProgress below where it was raised, not below its
// first raise (back at the light damping, xArm7 slid along a table at 1.3-1.7 rad/s, its
// hand's link closing on the table faster than its rows foresaw as it turned, and dipped
// 1.2 mm into the 10 mm margin, and one step took 1.7 times its acceleration limit, reported;
// never falling back, it left 11 of 144 starts inside a table's margin still moving at 8 s,
// UR10 at 0.2 rad/s).
void Controller::follow_damping(bool target_moved) {
  if (target_moved) forget_damping();
  if (goal_damping > 1.0 && std::sqrt(e_sq) < (1.0 - kDampedProgress) * damped_error) {
    goal_damping = std::max(goal_damping / kDampingGrowth, kDampingGrowth);
    damped_error = std::sqrt(e_sq);
  }
}

// No damping raised, nor a start from rest to judge against (reset; a target that moved).
void Controller::forget_damping() {
  damped_error = 1e300;
  goal_damping = 1.0;
  damping_raises = 0;
}

// Each joint clipped alone into its own box (acceleration, jerk, braking) bends the motion the
// feedback asks: from rest under a jerk limit, where every box is a sliver, the clipped
// velocity can move the task sideways or back. Before settle() brakes such a velocity, the
// velocity within the same box and the rows nearest the feedback's task motion along the
// projected steepest descent (the Cauchy point of |J0 (desired - v)|^2 from v, cut to the
// rows): it lowers that distance wherever any velocity within the box does, to first order.
// True: fit_v_ is that velocity.
bool Controller::fit_within_box(const Eigen::Ref<const RowMatrix>& J0,
                                const Eigen::Ref<const RowMatrix>& A,
                                const Eigen::Ref<const Vector>& b) {
  if (!feasible(velocity, A, b, box.lo, box.hi) || !held_kept(velocity)) return false;
  fit_lo_ = (box.lo - velocity).cwiseMin(0.0);
  fit_hi_ = (box.hi - velocity).cwiseMax(0.0);
  fit_v_ = desired - velocity;
  fit_a_.noalias() = J0 * fit_v_;
  cauchy_point(J0, fit_a_, fit_lo_, fit_hi_, kInf);
  double t = 1.0;
  for (Index i = 0; i < A.rows(); ++i) {
    const double au = A.row(i).dot(cauchy_);
    if (au > 0.0) t = std::min(t, (b[i] - A.row(i).dot(velocity)) / au);
  }
  if (!(t > 0.0)) return false;
  fit_v_ = velocity + t * cauchy_;
  return held_kept(fit_v_);
}

}  // namespace sjt
