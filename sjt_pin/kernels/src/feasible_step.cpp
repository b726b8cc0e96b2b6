// The nearest feasible step (controller.hpp): the first level's projection onto the box and the
// rows, its direction kept under acceleration limits, the held rows, and the smoothness limits
// yielding to a row.
#include "controller.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace sjt {

namespace {

// the share of the held rows' motion (1 + its norm) that counts as kept (the rows' own 1e-9)
constexpr double kHeldTol = 1e-9;
// under acceleration limits, keeping the task's direction is taken alone while it leaves at
// least this share of the progress the unconstrained projection makes (at most the whole step's)
constexpr double kUseful = 0.1;
// beta of the first projection: a task motion off the method's direction costs this much more
constexpr double kKeepDirection = 1e4;
// yield_smoothness: the factor tried first, above the least one each row needs alone; beyond
// the largest factor the hard box alone is taken (2 4^23, as far as the widening ever went)
constexpr double kWideningSlack = 1e-3;
constexpr double kWideningMost = 2.0 * 70368744177664.0;

}  // namespace

bool Controller::feasible(const Vector& x, const Eigen::Ref<const RowMatrix>& A,
                          const Eigen::Ref<const Vector>& b, const Vector& lo,
                          const Vector& hi) const {
  for (Index j = 0; j < nv; ++j)
    if (x[j] < lo[j] - kBoundTol || x[j] > hi[j] + kBoundTol) return false;
  for (Index i = 0; i < A.rows(); ++i)
    if (A.row(i).dot(x) > b[i] + kBoundTol * (1.0 + std::abs(b[i]))) return false;
  return true;
}

// The first level's step projected (see controller.hpp): the feasible velocity nearest the
// method's step in the method's metric (joints held at a bound, the others taking over; it lowers
// the error whenever some feasible velocity does), or under acceleration limits first along the
// method's direction (keep_direction); then the sufficient decrease (sufficient_decrease). The
// metric is the Hessian of the method's own objective where it has one (objective_rows): the
// former task-first metric (mu_T = 1e6) left the free joints' solve undamped, and at minima
// against the limits far from the target, where the method's damping is large, arms chattered
// for good (UR5 0.9 rad/s every 9 steps, xArm7 +-3.1 rad/s on alternate steps). The
// nearest velocity, not the step scaled along its direction: far from a target the method's step
// is hundreds of rad/s, and scaling it as a whole into the speed box moved one joint at its
// limit and the others in proportion, where the nearest feasible velocity drives every joint
// the task can use (measured: per step 1.5-1.7 times the task progress of the scaled step, the
// median over 200 random far targets on each of UR5, UR10, Panda and Kinova; Kinova's random
// full-range reaches missed within 5 s 50 -> 40 %, Panda's 47 -> 43 %). A joint without a speed
// limit is held within the norm of the method's whole step meanwhile. Then the lower levels,
// nearest their own step with the first level's task motion held; last, where a row is still
// broken, the nearest velocity within the whole box and the rows.
void Controller::project(const Eigen::Ref<const RowMatrix>& A, const Eigen::Ref<const Vector>& b,
                         const Vector& box_lo, const Vector& box_hi, bool hold) {
  const Level& top_level = levels[0];
  const auto J0 = Jw_.middleRows(top_level.begin, top_level.end - top_level.begin);
  // (the held rows as equalities in the hard box, where a velocity keeps them)
  const Index held_rows = hold ? held_.size() : 0;
  const auto H = J0.middleRows(top_level.targets, held_rows);
  const auto hd = held_.head(held_rows);
  const bool lower = levels.size() > 1;
  // a joint without a speed limit moves no faster than the method's whole step: beyond it the
  // step's linearisation means nothing (a continuous joint asked for 14,000 rad/s to make up
  // for the others' limits turned 14 rad in a step, and the error grew)
  const double cap = std::max(desired_top.norm(), desired.norm());
  plo_ = box_lo;
  phi_ = box_hi;
  for (Index j = 0; j < nv; ++j) {  // (a finite bound beyond the cap stays, and wins)
    if (std::isinf(phi_[j])) phi_[j] = std::max(cap, plo_[j]);
    if (std::isinf(plo_[j])) plo_[j] = std::min(-cap, phi_[j]);
  }
  const Vector& lo = plo_;
  const Vector& hi = phi_;
  x0_ = desired_top;
  bool inside = true;  // (projected_: whether it is not)
  for (Index j = 0; j < nv && inside; ++j)
    inside = desired_top[j] >= lo[j] - kBoundTol && desired_top[j] <= hi[j] + kBoundTol;
  for (Index i = 0; i < A.rows() && inside; ++i)
    inside = A.row(i).dot(desired_top) <= b[i] + kBoundTol * (1.0 + std::abs(b[i]));
  projected_ = !inside;
  if (!inside || !lower) {
    method.forget();
    tstar_.noalias() = J0 * desired_top;
    if (bounds.smooth) {
      keep_direction(J0, A, b, lo, hi, H, hd);
    } else {
      // (warm where the metric is the method's objective, J^T J plus its damping: there the
      // last step's dual point is a good start; the transpose feedback's metric weighs the
      // task 1e6 times the joints, and a dual point one step old took more Newton steps than
      // none: Kinova's circle with JT, 2.8 a step cold, 5.0 warm)
      const bool objective = method.objective_rows(J0, B_);
      if (!objective) method.metric(J0, top, tstar_, 0.0, B_);
      const ProjectionReport r =
          nearest.solve(desired_top, top.lam, B_, lo, hi, A, b, H, hd, x0_, objective);
      report.iterations += r.iterations;
      report.converged = report.converged && r.converged;
    }
    sufficient_decrease(J0, A, b, H, hd, desired_top.norm());
  }
  if (!lower) {
    velocity = x0_;
  } else {
    // the lower levels: nearest their task motion (lower_nearest), level 0's task motion held
    // (their step is in the null space of level 0's rows: where it is feasible, it is the
    // answer, and the projection is not run)
    tmp_ = x0_ + (desired - desired_top);
    if (feasible(tmp_, A, b, lo, hi)) {
      velocity = tmp_;
    } else {
      const ProjectionReport r = lower_nearest(J0, x0_, tmp_, A, b, lo, hi, velocity);
      report.iterations += r.iterations;
      report.converged = report.converged && r.converged;
    }
  }
  if (!rows_hold(A, b)) {
    // the task's metric can leave the dual degenerate (fewer joints inside their box than
    // task rows and rows to meet), and its solve stop short of a row: the nearest velocity
    // within the box and the rows (Euclidean, over the moving joints), whose dual has the
    // rows only; within the whole box (a row may need a joint without a speed limit faster
    // than the cap)
    tmp_ = velocity;
    ProjectionReport r = projection_.solve(tmp_, lam_low_, Bnone_, box_lo, box_hi, A, b, H, hd,
                                           velocity);
    report.iterations += r.iterations;
    report.converged = report.converged && r.converged;
  }
}

// Under acceleration limits, the first level's projection with its task motion kept along the
// method's (SNS's answer: joints held, the others taking over, in the method's metric); where
// that keeps less than kUseful of the progress the nearest feasible velocity without that
// constraint makes (which lowers the error whenever any feasible velocity does), blended toward
// it, fully where keeping the direction makes none (a joint at its limit that the others cannot
// replace). Each joint then brakes toward the displacement the method's feedback asks of it,
// which lies along that direction: the nearest feasible velocity alone, off it, sent the joints
// past their braking targets (measured on the jerk grid: 18 of 30 runs rested later than twice
// Ruckig's time, 2 never rested, where the direction kept leaves 2 late). Into x0_.
void Controller::keep_direction(const Eigen::Ref<const RowMatrix>& J0,
                                const Eigen::Ref<const RowMatrix>& A,
                                const Eigen::Ref<const Vector>& b, const Vector& lo,
                                const Vector& hi, const Eigen::Ref<const RowMatrix>& H,
                                const Eigen::Ref<const Vector>& hd) {
  // first the task's direction kept (a motion off it costs kKeepDirection times more)
  method.metric(J0, top, tstar_, kKeepDirection, B_);
  ProjectionReport r = projection_.solve(desired_top, top.lam, B_, lo, hi, A, b, H, hd, xa_);
  report.iterations += r.iterations;
  report.converged = report.converged && r.converged;
  const Eigen::MatrixXd& G = method.task_metric();
  gt_.noalias() = G * tstar_;
  const double tgt = tstar_.dot(gt_);
  tmp2_.noalias() = J0 * xa_;
  const double scale_direction = tgt > 0.0 ? tmp2_.dot(gt_) / tgt : 1.0;
  x0_ = xa_;
  // an upper bound of the unconstrained projection's progress: the box's best along G t*
  double reach = 0.0;
  if (tgt > 0.0) {
    direction_.noalias() = J0.transpose() * gt_;
    for (Index j = 0; j < nv; ++j) reach += direction_[j] * (direction_[j] > 0.0 ? hi[j] : lo[j]);
    reach /= tgt;
  }
  if (scale_direction < kUseful * reach) {
    // ... and the nearest feasible velocity in the method's metric alone: blended in where
    // keeping the direction makes little progress
    method.metric(J0, top, tstar_, 0.0, B_);
    r = projection_.solve(desired_top, top.lam, B_, lo, hi, A, b, H, hd, x0_);
    report.iterations += r.iterations;
    report.converged = report.converged && r.converged;
    tmp2_.noalias() = J0 * x0_;
    const double scale_free = tmp2_.dot(gt_) / tgt;
    const double w =
        scale_free > 0.0 ? std::clamp(scale_direction / (kUseful * scale_free), 0.0, 1.0) : 1.0;
    x0_ = w * xa_ + (1.0 - w) * x0_;
  }
}

// The first level's rows that hold (a contact: a task without a target) keep their motion,
// held_, after each joint's smoothness box: a joint clipped on its own would let a held foot
// slide (a quadruped's feet slid 1-5 cm under acceleration limits while its centre of mass
// moved, 10 cm under jerk limits). The nearest velocity (Euclidean over the moving joints)
// within the limits themselves, the hard box, each position range's braking and the
// acceleration/jerk box, without the braking's preferences (within those, the feet still
// slid), that keeps it. Where none does
// (a joint the contact needs held at a bound), the joints keep their own boxes' velocities:
// the least breach of the held rows drove the other joints to their bounds, the feet slid on
// and the acceleration limits gave way (a humanoid under jerk limits). True: it moved the
// velocity (within wide_lo_, wide_hi_).
bool Controller::hold_rows(const Eigen::Ref<const RowMatrix>& A,
                           const Eigen::Ref<const Vector>& b) {
  if (held_kept(velocity)) return false;
  for (Index j = 0; j < nv; ++j) {
    const double lo = std::max({box.hard_lo[j], box.brake_lo[j], box.cap_lo[j]});
    const double hi = std::min({box.hard_hi[j], box.brake_hi[j], box.cap_hi[j]});
    const bool apart = lo > hi;  // (then the combined box, where the hard bounds win)
    wide_lo_[j] = apart ? box.lo[j] : lo;
    wide_hi_[j] = apart ? box.hi[j] : hi;
  }
  const auto H = Jw_.middleRows(levels[0].begin + levels[0].targets, held_.size());
  tmp2_ = velocity;
  ProjectionReport r = projection_.solve(tmp2_, lam_low_, Bnone_, wide_lo_, wide_hi_, A, b, H,
                                         held_, velocity);
  report.iterations += r.iterations;
  if (r.converged && held_kept(velocity)) return true;
  velocity = tmp2_;
  return false;
}

// whether x keeps the first level's held rows' motion, held_
bool Controller::held_kept(const Vector& x) {
  if (held_.size() == 0) return true;
  held_res_.noalias() = Jw_.middleRows(levels[0].begin + levels[0].targets, held_.size()) * x;
  return (held_res_ - held_).norm() <= kHeldTol * (1.0 + held_.norm());
}

bool Controller::rows_hold(const Eigen::Ref<const RowMatrix>& A,
                           const Eigen::Ref<const Vector>& b) const {
  for (Index i = 0; i < A.rows(); ++i)
    if (A.row(i).dot(velocity) > b[i] + 1e-9 * (1.0 + std::abs(b[i]))) return false;
  return true;
}

// The projection within the hard box and the acceleration/jerk box widened s times about its
// centre (s = 1: the limits as given, without the braking's preferences); whether the rows hold.
bool Controller::rows_hold_within(double s, const Eigen::Ref<const RowMatrix>& A,
                                  const Eigen::Ref<const Vector>& b) {
  for (Index j = 0; j < nv; ++j) widened(box, j, s, wide_lo_[j], wide_hi_[j]);
  project(A, b, wide_lo_, wide_hi_, false);
  return rows_hold(A, b);
}

// Rows that no velocity within the smoothness box meets (a collision row, a user's hard row):
// the acceleration and jerk limits yield, by the least factor (to 1 %) that lets the rows hold,
// widened about the box's centre on every joint alike; the hard box alone where even that
// fails, if there they hold; where not even the hard box keeps them all (a ball between two
// links, each of whose rows could be kept alone), the limits hold: yielding would keep no
// row that they break (a ball at SO-101's forearm drove every joint to +-10 rad/s a step).
// The factor each row needs alone (least_widening, a scalar search) bounds it from below, and
// is the answer where one row binds or the rows do not compete: two projections. Otherwise
// bisected from there: at most 6 + 2 log2(s) + 7 more, in the steps that need them (bisected
// from 1, UR5 starting 1 mm beyond a user's row ran up to 20 projections, 376 Newton steps, in
// a step; 167 now).
void Controller::within_hard_box(const Eigen::Ref<const RowMatrix>& A,
                                 const Eigen::Ref<const Vector>& b) {
  for (Index j = 0; j < nv; ++j) {  // (within each range's braking at the whole limits too)
    wide_lo_[j] = box.hard_lo[j];
    wide_hi_[j] = box.hard_hi[j];
    within_stopping(box, j, wide_lo_[j], wide_hi_[j]);
  }
  project(A, b, wide_lo_, wide_hi_, true);
  if (!rows_hold(A, b)) project(A, b, box.lo, box.hi, false);
}

void Controller::yield_smoothness(const Eigen::Ref<const RowMatrix>& A,
                                  const Eigen::Ref<const Vector>& b) {
  if (rows_hold_within(1.0, A, b)) return;
  double need = 1.0;
  for (Index i = 0; i < A.rows(); ++i)
    need = std::max(need, least_widening(box, A.row(i).transpose(), b[i]));
  if (!(need <= kWideningMost)) {  // (no widening meets a row, or none short of the hard box)
    within_hard_box(A, b);
    return;
  }
  // (a little inside the rows, whose boundary leaves the projection's dual degenerate)
  if (rows_hold_within(need * (1.0 + kWideningSlack), A, b)) return;
  double low = need * (1.0 + kWideningSlack), high = 2.0 * low;
  bool found = false;
  for (int k = 0; k < 24 && !found && high <= kWideningMost; ++k) {
    found = rows_hold_within(high, A, b);
    if (!found) {
      low = high;
      high *= 4.0;
    }
  }
  if (!found) {
    within_hard_box(A, b);
    return;
  }
  while (high > 1.01 * low) {
    const double s = std::sqrt(low * high);
    if (rows_hold_within(s, A, b)) high = s;
    else low = s;
  }
  rows_hold_within(high, A, b);
}

}  // namespace sjt
