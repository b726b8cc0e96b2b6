// One CLIK step after the tasks (controller.hpp).
#include "controller.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace sjt {

namespace {

constexpr double kBoundTol = 1e-12;  // rad/s: a velocity this close to a bound is on it
// the share of the held rows' motion (1 + its norm) that counts as kept (the rows' own 1e-9)
constexpr double kHeldTol = 1e-9;
// under acceleration limits, keeping the task's direction is taken alone while it leaves at
// least this share of the progress the unconstrained projection makes (at most the whole step's)
constexpr double kUseful = 0.1;
// beta of the first projection: a task motion off the method's direction costs this much more
constexpr double kKeepDirection = 1e4;
// the projection keeps at least this share of the progress of the Cauchy point (the steepest
// feasible progress within a ball of the method's own step size)
constexpr double kSufficient = 0.25;
// 1/s: a step that lowers 1/2 |e_w|^2 by less than this share of |e_w|^2 per second makes no
// progress (StepInfo's STALL_RATE, sjt_pin.step_info)
constexpr double kStallRate = 1e-6;
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
constexpr double kRestRate = 1e-3;
// settle: a motion whose first-order decrease of the error is below this share of
// |e_w| |J0 v| is one the model cannot tell from an increase (the pose error's log bends the
// map from J0 v to the error's rate by about |e_w| / 2 of |J0 v|). xArm7 behind an obstacle
// under acceleration and jerk limits (blocked seed 1, DLS) slid at 0.05 rad/s with its error
// growing by 2e-4 per second, where the model promised a decrease of 1e-3 of |e_w| |J0 v|;
// 3e-3 stopped xArm6's blocked seed 2 (SJT) at an error of 0.176 where 1e-3 lets it reach 0.107
constexpr double kAligned = 1e-3;
// the share of a step's first-order decrease of 1/2 |e_w|^2 that the measured second-order
// term may take (trusted_share)
constexpr double kTrust = 0.5;
// range_goal's damping, relative to the first level's mean squared column norm: a floor, and
// a Levenberg-Marquardt term that grows with |e_w| (per task unit). Measured on held targets
// beyond a position range under jerk limits (30 runs on UR5, Panda, UR10, KUKA iiwa and
// xArm6, DLS): still moving after 12 s in 6 runs with the floor alone (near a singularity the
// displacement's huge self-motion share sent the arm to and fro at up to 1.7 rad/s), 2 with
// 0.5, 3 with 2 (the two left converging slowly along a shallow valley, the error falling)
constexpr double kGoalFloor = 1e-6;
constexpr double kGoalDamping = 0.5;
// yield_smoothness: the factor tried first, above the least one each row needs alone; beyond
// the largest factor the hard box alone is taken (2 4^23, as far as the widening ever went)
constexpr double kWideningSlack = 1e-3;
constexpr double kWideningMost = 2.0 * 70368744177664.0;

}  // namespace

Controller::Controller(const MethodParameters& method_, Index rows, Index nv_, Index nq_,
                       double dt, const Vector& sqrt_weight_, const Vector& gains_,
                       const Vector& moving_, Index error_rows_,
                       const std::vector<Level>& levels_, const BoundsConfig& bounds_,
                       double stall_ratio_, double stall_floor_, const Vector& rank_scale_)
    : m(rows), nv(nv_), nq(nq_), error_rows(error_rows_), sqrt_weight(sqrt_weight_),
      gains(gains_), moving(moving_), rank_scale(rank_scale_), levels(levels_), bounds(bounds_),
      stall_ratio(stall_ratio_), stall_floor(stall_floor_), dt_(dt) {
  method.p = method_;
  lower_.p = method_;
  lower_.p.damped_feedback = true;  // lower levels solve for their task velocity
  lower_.p.lm = 0.0;
  if (sqrt_weight.size() != m || gains.size() != m || rank_scale.size() != m)
    fail("sqrt_weight, gains and rank_scale must have one entry per row");
  if (moving.size() != nv) fail("moving must have one entry per velocity coordinate");
  if (levels.empty()) levels.push_back(Level{0, m, false, error_rows});
  Index expect = 0;
  for (const Level& l : levels) {
    if (l.begin != expect || l.end < l.begin || l.end > m || l.targets > l.end - l.begin)
      fail("levels must cover the rows in order, each (begin, end, identity, targets)");
    if (l.identity && l.end - l.begin != nv) fail("an identity level has one row per joint");
    expect = l.end;
  }
  if (expect != m) fail("levels must cover every row");
  if (levels[0].identity) fail("the first level cannot be a posture's identity rows alone");
  for (const Level& l : levels) has_posture_ = has_posture_ || l.identity;
  bounds.nv = nv;
  if (bounds.speed.size() != nv || bounds.moving.size() != nv) fail("bounds: speed and moving need nv entries");
  if (bounds.smooth && (bounds.acceleration.size() != nv || bounds.jerk.size() != nv))
    fail("bounds: acceleration and jerk need nv entries");
  for (const PositionRange& r : bounds.ranges)
    if (r.q < 0 || r.q >= nq || r.v < 0 || r.v >= nv) fail("bounds: a position range's index is out of range");
  dq.setZero(nv);
  ddq.setZero(nv);
  escape_velocity.setZero(nv);
  for (Vector* v : {&desired, &fb, &ff, &velocity, &fb0_, &ff0_, &desired_top, &x0_, &xa_,
                    &tmp_, &tmp2_, &lam_low_, &low_p_, &low_h_, &low_d_, &low_dh_, &low_dinv_,
                    &anchor_, &coef_, &wide_lo_, &wide_hi_, &rest_, &holding})
    v->setZero(nv);
  basis_.setZero(nv, nv);
  const Index r0 = levels[0].end - levels[0].begin;
  loop_.setZero(r0, r0);
  kew_.setZero(r0);
  Jw_.resize(m, nv);
  ew_.resize(m);
  ffw_.resize(m);
  Bnone_.resize(0, nv);
  box.resize(nv);
  for (Index j = 0; j < nv; ++j) lam_low_[j] = moving[j] != 0.0 ? 1.0 : kInf;
  // (Eigen's LLT leaves its status unset until a first compute, and a copy or move of the
  // controller reads it: UBSan's invalid enum load)
  low_llt_.compute(Eigen::MatrixXd::Identity(1, 1));
  goal_llt_.compute(Eigen::MatrixXd::Identity(1, 1));
  lock_llt_.compute(Eigen::MatrixXd::Identity(1, 1));
}

void Controller::set_gains(const Vector& gains_, bool auto_gain, double factor) {
  if (gains_.size() != m) fail("gains must have one entry per row");
  gains = gains_;
  method.p.auto_gain = lower_.p.auto_gain = auto_gain;
  method.p.gain_factor = lower_.p.gain_factor = factor;
}

void Controller::set_speed(const Vector& speed) {
  if (speed.size() != nv) fail("speed must have one entry per velocity coordinate");
  for (Index j = 0; j < nv; ++j)
    if (std::isnan(speed[j]) || speed[j] < 0.0) fail("speed limits must be >= 0 (inf: none)");
  bounds.speed = speed;
}

void Controller::reset() {
  dq.setZero();
  ddq.setZero();
  escape_velocity.setZero();
  escaping = false;
  stall_run = -1.0;
  stall_wait = 1e300;
  nearest.forget();
  bent_ready_ = false;
}

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

// The sufficient decrease of trust-region methods. The model is the linearised error after the
// step, m(v) = |a - J0 v|^2 dt^2, a = e_w / dt and the feed-forward (whatever the gains). Its
// Cauchy point (cauchy_point) is the model's first minimum along the projected steepest
// descent within a ball of the method's own step size. Where x0_ lowers the model by less than
// kSufficient of what that point does (the metric of the projection can weigh the joints that
// could carry the task heavily: a joint at its limit then froze the step), x0_ is blended
// toward it: the model is convex, so the step then lowers it by at least that share. A best
// decrease below a stalled step's (kStallRate) counts as none, and the Cauchy point is then 0:
// an x0_ that raises the model gives way to it, and the arm rests at its minimum against the
// limits (the decision no longer turns on whether that decrease rounds to 0 or to 1e-16 of
// |a|^2, which gave the same motion in mm and in m different steps). A Cauchy point that
// breaks a row or lets a held row go is not taken (the projection's own rows stand), nor is
// one where the box does not hold 0 (a joint returning into its range). The Cauchy point is
// cut by the measured curvature as a projected step is (trusted_share), and the decrease the
// stall rule judges is the cut point's. Before that, an x0_
// that lowers the model by less than a resting arm does (kRestRate) gives way to rest; H, hd:
// the held rows and their motion, which the rest keeps.
void Controller::sufficient_decrease(const Eigen::Ref<const RowMatrix>& J0,
                                     const Eigen::Ref<const RowMatrix>& A,
                                     const Eigen::Ref<const Vector>& b,
                                     const Eigen::Ref<const RowMatrix>& H,
                                     const Eigen::Ref<const Vector>& hd, double ball) {
  if (!(ball > 0.0)) return;
  for (Index j = 0; j < nv; ++j)
    if (plo_[j] > 0.0 || phi_[j] < 0.0) return;
  cauchy_point(J0, ball);
  {
    // (the Cauchy point too, no further than its first-order decrease outweighs the
    // second-order term the last step measured: the model's minimum along the steepest
    // descent lies beyond the error's where the kinematics bend)
    tmp2_.noalias() = J0 * cauchy_;
    const double share = trusted_share(J0, wanted_.dot(tmp2_), tmp2_.squaredNorm(),
                                       cauchy_.squaredNorm());
    if (share < 1.0) cauchy_ *= share;
  }
  const double aa = wanted_.squaredNorm();
  res_ = wanted_;
  res_.noalias() -= J0 * cauchy_;
  double best = aa - res_.squaredNorm();
  if (best < 2.0 * kStallRate * dt_ * aa) {  // (the decrease of a stalled step: none)
    best = 0.0;
    cauchy_.setZero(nv);
  }
  // x0_ no further along its own direction than the model's minimum there, nor than its
  // first-order decrease outweighs the second-order term the last step measured
  tmp2_.noalias() = J0 * x0_;
  const double along = wanted_.dot(tmp2_), curvature = tmp2_.squaredNorm();
  const double share = std::min(along < curvature ? std::max(along, 0.0) / curvature : 1.0,
                                trusted_share(J0, along, curvature, x0_.squaredNorm()));
  if (share < 1.0) {
    xa_ = share * x0_;
    if (feasible(xa_, A, b, plo_, phi_) && held_kept(xa_)) {
      x0_ = xa_;
      tmp2_.noalias() = J0 * x0_;
    }
  }
  res_ = wanted_ - tmp2_;
  double progress = aa - res_.squaredNorm();
  // a step below a resting arm's progress (kRestRate) gives way to the least motion within
  // the limits (0 where 0 is feasible: a row the arm is inside of pushes it out), fully at
  // kRestRate and not at all at twice that, so that the velocity stays continuous in q. Under
  // acceleration limits only where 0 is feasible: each joint brakes toward the projection's
  // answer there, and toward the least motion that keeps the rows a ball driven at Panda's
  // hand at 0.5 m/s got close enough that the rows then took the arm past its acceleration
  // (1.08x) and jerk (1.17x) limits. Not while an escape (or a settling step) is added: its
  // test found the error lower along it, where the linearised model sees little progress
  // (TIAGo's arm 1 m beyond reach, the torso at its range: a settling step whose model
  // progress was 3e-8 of |e_w|^2 a step rested at once, 7e-7 of the error short of where the
  // arm was going), and it yields by itself if the error grows
  const double rest = 2.0 * kRestRate * dt_ * aa;
  if (progress < 2.0 * rest && !escaping) {
    rest_.setZero(nv);
    const bool still = feasible(rest_, A, b, plo_, phi_) && held_kept(rest_);
    if (still || !bounds.smooth) {
      if (!still) {
        xa_.setZero(nv);
        ProjectionReport r = projection_.solve(xa_, lam_low_, Bnone_, plo_, phi_, A, b, H, hd,
                                               rest_);
        report.iterations += r.iterations;
      }
      const double w = std::clamp(progress / rest - 1.0, 0.0, 1.0);
      holding = x0_;
      rested_ = true;
      x0_ = w * x0_ + (1.0 - w) * rest_;
      tmp2_.noalias() = J0 * x0_;
      res_ = wanted_ - tmp2_;
      progress = aa - res_.squaredNorm();
    }
  }
  if (!(best >= 0.0) || progress >= kSufficient * best) return;
  if (!feasible(cauchy_, A, b, plo_, phi_)) return;
  if (!held_kept(cauchy_)) return;
  const double w = progress > 0.0 ? progress / (kSufficient * best) : 0.0;
  x0_ = w * x0_ + (1.0 - w) * cauchy_;
}

// The share t in [0, 1] of a step x (a . J0 x = along, |J0 x|^2 = jj, |x|^2 = xx) whose
// first-order decrease of 1/2 |e_w|^2 is at least twice the second-order term the
// Gauss-Newton model leaves out, -1/2 e_w . d2x(x, x) dt^2 (the residual times the kinematics'
// curvature). The last step measured it along its own velocity u: (J0 - J0_last) u =
// d2x(u, u) dt to first order, and a step x is taken to bend as much per |x|^2. Far beyond
// reach, with a joint at its position range, the joints left free could move the hand only
// across the error, where that term is as large as the first-order decrease (xArm6 from
// pybullet's URDF and Panda, targets 1.5 m straight out from q0: SJT, JP and JT moved the
// hand at 0.3-1.3 m/s at the speed limits, turning back every step or two, for good; KUKA
// iiwa's JT at 10 rad/s). Only a projected step (the method's own stands), and only where the
// term raises the error:  2 t along - t^2 jj >= t^2 bend xx / kTrust.
double Controller::trusted_share(const Eigen::Ref<const RowMatrix>& J0, double along,
                                 double jj, double xx) {
  if (!bent_ready_ || !projected_) return 1.0;
  const double uu = dq.squaredNorm();
  if (!(uu > 0.0) || bent_.size() != J0.rows()) return 1.0;
  bent_now_.noalias() = J0 * dq;
  const double bend =
      -ew_.segment(levels[0].begin, J0.rows()).dot(bent_now_ - bent_) / (dt_ * uu);
  if (!(bend > 0.0)) return 1.0;
  const double second = bend * xx / kTrust + jj;
  return second > 0.0 ? std::clamp(2.0 * along / second, 0.0, 1.0) : 1.0;
}

// Under acceleration limits each joint brakes so that it can stop at the displacement the
// first level's feedback asks of it (fb / K), and approaches the feedback's velocity. Where that
// displacement takes a joint past its position range, the others' shares of it assume a motion
// the range forbids: chasing them, the arm passed the constrained minimum of the error and
// turned back, again and again (held targets beyond a position range under jerk limits, 30
// runs on UR5, Panda, UR10, KUKA iiwa and xArm6: 24 still moved after 12 s, at up to
// 2.5 rad/s). There the first level's feedback is instead K times the damped least-squares
// displacement within the ranges (Levenberg-Marquardt with bounds),
//     min |J0 d - e_w|^2 + mu |d|^2   s.t.   lower - q <= d <= upper - q,
// solved as the point nearest its unconstrained minimiser in the metric mu I + J0^T J0, the
// rows weighted by their gains as in the method's feedback, the held rows (contacts) kept at
// the motion the method asks of them as equalities. At a constrained stationary point of the
// error it is 0, and every joint brakes to rest there. The lower levels are then computed on
// it. The general rows whose `room` is given (A d <= room: a collision pair's distance less its
// margin; NaN or inf: a row of velocity only) bound it too, by min(room, b / K), what the row's
// velocity bound lets the gain cover, and one the displacement breaks also calls for it: an arm
// whose target lies behind an obstacle slid along it under acceleration limits (16 of 18
// blocked scenes on KUKA iiwa, xArm6 and UR3 still moved after 8 s; with the room, none).
// True: it replaced the feedback (its box holds 0: a joint outside its range returns by the
// position bounds; a row's room is at least 0: a pair inside its margin moves out by its
// velocity rows).
bool Controller::range_goal(const Eigen::Ref<const RowMatrix>& J0, const double* q, double K,
                            bool user, const Eigen::Ref<const RowMatrix>& A,
                            const Eigen::Ref<const Vector>& b, const double* room) {
  // (a joint outside its range counts only where the displacement takes it further out; a
  // row already broken, only where the displacement breaks it further)
  bool crosses = false;
  for (const PositionRange& r : bounds.ranges)
    crosses = crosses || (moving[r.v] != 0.0 && leaves_range(r, q[r.q], fb0_[r.v] / K));
  const Index k = room ? A.rows() : 0;
  goal_room_.resize(k);
  for (Index i = 0; i < k; ++i) {
    goal_room_[i] = std::isfinite(room[i]) ? std::max(std::min(room[i], b[i] / K), 0.0) : kInf;
    if (!crosses && std::isfinite(goal_room_[i])) {
      const double closing = A.row(i).dot(fb0_) / K;
      crosses = closing > goal_room_[i];
    }
  }
  if (!crosses) return false;
  const Level& L0 = levels[0];
  const Index r0 = J0.rows(), targets = L0.targets, held = r0 - targets;
  // the rows' own gains weigh them as in the method's feedback (K e_w, over the mean gain)
  goal_e_ = ew_.segment(L0.begin, r0);
  if (!user) goal_e_.array() *= gains.segment(L0.begin, r0).array() * (top.gain / K);
  const double mu = (kGoalFloor + kGoalDamping * goal_e_.head(targets).norm()) *
                    std::max(J0.squaredNorm() / static_cast<double>(nv), 1e-300);
  goal_gram_.noalias() = J0 * J0.transpose();
  goal_gram_.diagonal().array() += mu;
  goal_llt_.compute(goal_gram_);
  goal_y_ = goal_llt_.solve(goal_e_);
  goal_xb_.noalias() = J0.transpose() * goal_y_;
  goal_lam_.resize(nv);
  for (Index j = 0; j < nv; ++j) goal_lam_[j] = moving[j] != 0.0 ? mu : kInf;
  range_box(q, goal_lo_, goal_hi_);
  // the held rows (contacts) keep the motion the method asks of them, as equalities
  const auto C = J0.middleRows(targets, held);
  goal_d_.noalias() = C * fb0_;
  goal_d_ /= K;
  goal_.resize(nv);
  const ProjectionReport report_goal =
      k > 0 ? projection_.solve(goal_xb_, goal_lam_, J0, goal_lo_, goal_hi_, A, goal_room_, C,
                                goal_d_, goal_)
            : projection_.solve(goal_xb_, goal_lam_, J0, goal_lo_, goal_hi_, Bnone_,
                                goal_y_.head(0), C, goal_d_, goal_);
  if (!report_goal.converged || !goal_.allFinite()) return false;
  goal_rows_ = report_goal.rows_active > 0;
  method_top_ = fb0_ + ff0_;
  fb0_ = K * goal_;
  return true;
}

// Where range_goal replaced the feedback and a row's room binds it, a velocity that lowers
// 1/2 |e_w|^2 by less than a resting arm does (kRestRate), or by less than the model can vouch
// for (kAligned), gives way to braking to rest, as a projected step does
// (sufficient_decrease): fully at that rate, not at all at twice it (both velocities keep the
// rows, and so does their blend; the progress counts the feed-forward's motion too: judging
// the feedback's share alone stopped UR3 while its target still moved). Each joint brakes toward its own share of the displacement, which bends the motion
// away from it; against an obstacle, whose rows' room is linearised anew each step, Panda's
// arm slid along it at 0.045 rad/s for seconds while lowering its error by 6e-7 of itself per
// second (blocked seed 11 under acceleration limits), where the displacement promised 30
// times more. (Not where the ranges alone bind it: those rates also fall while the arm closes
// in on the constrained minimum, and it stopped 1e-4 short of stationarity on UR5, UR10 and
// Panda, and 3.5e-3 short of xArm7's final target in the stream of `bench accuracy`.)
void Controller::settle(const Eigen::Ref<const RowMatrix>& J0, const double* q,
                        const Eigen::Ref<const RowMatrix>& A, const Eigen::Ref<const Vector>& b,
                        const double* user_lo, const double* user_hi) {
  const Index targets = levels[0].targets;
  if (targets == 0) return;
  goal_y_.noalias() = J0 * velocity;
  const auto e = goal_e_.head(targets), moved = goal_y_.head(targets);
  const double rate = e.dot(moved);
  const double rest = std::max(kRestRate * e.squaredNorm(), kAligned * e.norm() * moved.norm());
  if (!(rate < 2.0 * rest)) return;
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

// The generalized Cauchy point (Byrd, Lu, Nocedal and Zhu 1995, section 4) of m within the box
// (plo_, phi_, which holds 0) and |v| <= ball: along v(s) = clip(s d, lo, hi), d = J0^T a,
// segment by segment between the joints' breakpoints (where each reaches its bound), the first
// minimum of the quadratic m(v(s)), or where v(s) leaves the ball. Into cauchy_.
void Controller::cauchy_point(const Eigen::Ref<const RowMatrix>& J0, double ball) {
  descent_.noalias() = J0.transpose() * wanted_;
  const Vector& d = descent_;
  breaks_.clear();
  free_ = d;
  for (Index j = 0; j < nv; ++j) {
    const double bound = d[j] > 0.0 ? phi_[j] : plo_[j];
    const double t = d[j] != 0.0 ? bound / d[j] : kInf;
    if (!(t > 0.0)) free_[j] = 0.0;  // at its bound already (d_j = 0: t is inf, free_j is 0)
    else if (std::isfinite(t)) breaks_.emplace_back(t, j);
  }
  std::sort(breaks_.begin(), breaks_.end());
  cauchy_.setZero(nv);
  res_ = wanted_;                   // a - J0 v
  jd_.noalias() = J0 * free_;       // J0 d_F
  double vv = 0.0, vd = 0.0, dd = free_.squaredNorm(), s = 0.0;
  const double rr = ball * ball;
  std::size_t k = 0;
  while (dd > 0.0) {
    const double next = k < breaks_.size() ? breaks_[k].first : kInf;
    const double jj = jd_.squaredNorm(), slope = res_.dot(jd_);
    if (!(slope > 0.0)) break;                      // the model no longer falls along the path
    double tau = jj > 0.0 ? slope / jj : kInf;      // the segment's minimum
    const double disc = vd * vd - dd * (vv - rr);   // where |v + tau d_F| = ball
    tau = std::min(tau, disc > 0.0 ? (std::sqrt(disc) - vd) / dd : 0.0);
    if (tau <= next - s) {
      cauchy_ += tau * free_;
      return;
    }
    const double step = next - s;                   // on to the breakpoint: its joint stops
    cauchy_ += step * free_;
    res_ -= step * jd_;
    s = next;
    for (; k < breaks_.size() && breaks_[k].first <= s; ++k) {
      const Index j = breaks_[k].second;
      cauchy_[j] = d[j] > 0.0 ? phi_[j] : plo_[j];
      jd_ -= free_[j] * J0.col(j);
      dd -= free_[j] * free_[j];
      free_[j] = 0.0;
    }
    if (k == breaks_.size()) return;  // every joint at its bound (the box is finite: capped)
    vv = cauchy_.squaredNorm();
    vd = cauchy_.dot(free_);
  }
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
// widened about the box's centre on every joint alike; the hard box alone where even that fails.
// The factor each row needs alone (least_widening, a scalar search) bounds it from below, and
// is the answer where one row binds or the rows do not compete: two projections. Otherwise
// bisected from there: at most 6 + 2 log2(s) + 7 more, in the steps that need them (bisected
// from 1, UR5 starting 1 mm beyond a user's row ran up to 20 projections, 376 Newton steps, in
// a step; 167 now).
void Controller::yield_smoothness(const Eigen::Ref<const RowMatrix>& A,
                                  const Eigen::Ref<const Vector>& b) {
  if (rows_hold_within(1.0, A, b)) return;
  double need = 1.0;
  for (Index i = 0; i < A.rows(); ++i)
    need = std::max(need, least_widening(box, A.row(i).transpose(), b[i]));
  if (!(need <= kWideningMost)) {  // (no widening meets a row, or none short of the hard box)
    project(A, b, box.hard_lo, box.hard_hi, true);
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
    project(A, b, box.hard_lo, box.hard_hi, true);
    return;
  }
  while (high > 1.01 * low) {
    const double s = std::sqrt(low * high);
    if (rows_hold_within(s, A, b)) high = s;
    else low = s;
  }
  rows_hold_within(high, A, b);
}

// A method of the user's: q_dot = M (k e_w scaled + ff_w) on the first level's weighted rows
// J0, with "auto" k = c / (dt lambda_hat), lambda_hat the largest eigenvalue of the symmetric
// part of J0 M (>= the real part of each of J0 M's eigenvalues; exact where J0 M is symmetric,
// as for M = S J0^T or a pseudoinverse)
void Controller::map_matrix(const Eigen::Ref<const RowMatrix>& J0, const double* matrix,
                            bool with_ff) {
  const Level& L0 = levels[0];
  const Index r0 = L0.end - L0.begin;
  const Eigen::Map<const RowMatrix> M(matrix, nv, r0);
  const auto k0 = gains.segment(L0.begin, r0);
  double scale = 1.0;
  if (method.p.auto_gain) {
    loop_.noalias() = J0 * M;
    const double lambda = method.symmetric_top(loop_);
    scale = lambda > 0.0 ? method.p.gain_factor / (dt_ * lambda) : 0.0;
    top.loop_bound = lambda;
  }
  top.gain = scale;
  kew_ = scale * k0.cwiseProduct(ew_.segment(L0.begin, r0));
  fb0_.noalias() = M * kew_;
  if (with_ff) ff0_.noalias() = M * ffw_.segment(L0.begin, r0);
  else ff0_.setZero();
  const Index counted = std::min<Index>(std::max<Index>(L0.targets, 1), r0);
  given_gain = counted > 0 ? scale * k0.head(counted).mean() : 0.0;
}

// The box of displacements within the position ranges from q, lower - q <= d <= upper - q, widened
// to hold 0 (a joint outside its range returns by the position bounds); unbounded elsewhere.
void Controller::range_box(const double* q, Vector& lo, Vector& hi) const {
  lo.setConstant(nv, -kInf);
  hi.setConstant(nv, kInf);
  for (const PositionRange& r : bounds.ranges) {
    lo[r.v] = std::min(r.lower - q[r.q], 0.0);
    hi[r.v] = std::max(r.upper - q[r.q], 0.0);
  }
}

// A joint a bounded displacement d holds at its range end (d at lo or hi) is held by the
// range, whatever bound (the braking toward that displacement) is the tighter one at rest there.
void Controller::held_by_ranges(const Vector& d, const Vector& lo, const Vector& hi) {
  for (const PositionRange& r : bounds.ranges) {
    const Index j = r.v;
    if (d[j] >= hi[j] && box.hi_by[j] == kBraking) box.hi_by[j] = kPosition;
    if (d[j] <= lo[j] && box.lo_by[j] == kBraking) box.lo_by[j] = kPosition;
  }
}

int Controller::run(const Eigen::Ref<const RowMatrix>& J, const Eigen::Ref<const Vector>& e,
                    const double* ff_in, const double* q, Eigen::Ref<Vector> step,
                    const double* matrix, const double* user_lo,
                    const double* user_hi, const Eigen::Ref<const RowMatrix>& A,
                    const Eigen::Ref<const Vector>& b, const double* room) {
  const Index n = nv;
  // 1. the weighted rows of the moving joints
  Jw_.noalias() = sqrt_weight.asDiagonal() * J * moving.asDiagonal();
  ew_ = sqrt_weight.cwiseProduct(e);
  // |e|^2 of the target rows, summed in order (as the logs' norms are)
  e_sq = 0.0;
  for (const Level& l : levels)
    for (Index i = l.begin; i < l.begin + l.targets; ++i) e_sq += e[i] * e[i];
  ff_sq = 0.0;
  if (ff_in) {
    for (Index i = 0; i < m; ++i) {
      ffw_[i] = sqrt_weight[i] * ff_in[i];
      ff_sq += ff_in[i] * ff_in[i];
    }
  }
  if (!std::isfinite(e_sq + ff_sq)) return kNonFinite;
  // 2. the first level's method
  const Level& L0 = levels[0];
  const Index r0 = L0.end - L0.begin;
  const auto J0 = Jw_.middleRows(L0.begin, r0);
  method.prepare(J0, ew_.segment(L0.begin, r0), gains.segment(L0.begin, r0), L0.targets, dt_, top);
  if (matrix) {
    map_matrix(J0, matrix, ff_in != nullptr);
  } else {
    if (ff_in) {
      method.both(J0, ew_.segment(L0.begin, r0), gains.segment(L0.begin, r0),
                  ffw_.segment(L0.begin, r0), top, fb0_, ff0_);
    } else {
      method.feedback(J0, ew_.segment(L0.begin, r0), gains.segment(L0.begin, r0), top, fb0_);
      ff0_.setZero();
    }
  }
  if (!fb0_.allFinite() || !ff0_.allFinite()) return kNonFinite;
  // the task velocity that removes level 0's error in this step (and follows the target's
  // motion): the model of the stage's sufficient decrease, |wanted - J0 v|^2 dt^2, is then the
  // linearised error after the step, whatever the method's gain
  wanted_ = ew_.segment(L0.begin, r0) / dt_;
  if (ff_in) wanted_ += ffw_.segment(L0.begin, r0);
  regular = (fb0_ + ff0_).norm();
  int status = 0;
  // the stall the escape watches (transpose methods): the loop gain along the command below
  // stall_ratio of its trace while the error is above the floor; Python hears of the first
  // stalled step of a run and of each window's end
  if (stall_ratio >= 0.0 && top.stall < stall_ratio && top.ew_sq > stall_floor) {
    if (stall_run < 0.0) {
      stall_run = 1.0;
      status |= kStalled;
    } else if ((stall_run += 1.0) >= stall_wait) {
      status |= kStalled;
    }
  } else {
    stall_run = -1.0;
  }
  if (escaping) ff0_ += escape_velocity;
  // under acceleration limits, a first-level displacement past a position range gives way to
  // the bounded least-squares one (range_goal; the method's own velocity stays in method_top_)
  const Index counted = L0.targets > 0 ? L0.targets : r0;
  const double K = matrix ? given_gain
                          : (counted > 0 ? gains.segment(L0.begin, counted).mean() : 0.0) *
                                top.gain;
  replaced_ = bounds.smooth && K > 0.0 && range_goal(J0, q, K, matrix != nullptr, A, b, room);
  // 3. the lower levels
  fb = fb0_;
  ff = ff0_;
  desired_top = fb0_ + ff0_;
  if (levels.size() > 1) lower_levels(ff_in ? ffw_.data() : nullptr, q);
  lower_replaced_ = bounds.smooth && K > 0.0 && levels.size() > 1 &&
                    lower_goal(J0, q, K, A, room != nullptr);
  desired = fb + ff;
  // the first level's rows that hold (a contact: a task without a target) are equalities of
  // every projection below, at the motion the first level asks of them
  const Index held = L0.end - L0.begin - L0.targets;
  held_.noalias() = J0.middleRows(L0.targets, held) * desired_top;
  // 4. each joint's box: what it can do this step, and the braking that lets it stop where the
  // feedback sends it (the displacement fb / K it asks of each)
  capability(bounds, dt_, dq, ddq, box);
  if (bounds.smooth && K > 0.0) {
    delta_ = fb / K;
  } else {
    delta_.setZero(n);
  }
  joint_box(bounds, dt_, q, dq, fb, ff, delta_, user_lo, user_hi, box);
  bool torn = false;
  for (Index j = 0; j < n; ++j) torn = torn || box.torn[j];
  if (torn) status |= kConflict;
  // a row that no velocity within the hard box keeps (a link its joints cannot move away from
  // an obstacle, an obstacle faster than the speed limits) asks what the box allows at best:
  // kept alone, it does not tear the others apart (StepInfo.rows_exceeded reports the row as
  // given)
  const Index k = A.rows();
  bk_.resize(k);
  for (Index i = 0; i < k; ++i) {
    double best = 0.0;
    for (Index j = 0; j < n; ++j) {
      const double a = A(i, j);
      if (a != 0.0) best += a * (a > 0.0 ? box.hard_lo[j] : box.hard_hi[j]);
    }
    bk_[i] = std::max(b[i], best);
  }
  const Vector& bk = bk_;
  // 5. the method's step where it is within every limit; else first the hard limits (position,
  // speed, a user's bounds and rows) by the projection, where joints held at a bound leave the
  // task to the others; then each joint's smoothness box (acceleration, jerk, braking) on its
  // own, the hard box winning where the two are apart: each joint follows its jerk-limited
  // braking profile toward where the feedback sends it (redistributing what a braking joint
  // leaves to the others would bring its share of the error back step after step); and where
  // that breaks a row, the projection within the whole box, or the hard box alone (the
  // smoothness yields to a collision row).
  report = ProjectionReport{};
  rested_ = false;
  kept = feasible(desired, A, bk, box.lo, box.hi);
  if (kept) {
    velocity = desired;
  } else {
    status |= kConstrained;
    if (feasible(desired, A, bk, box.hard_lo, box.hard_hi)) {
      velocity = desired;
    } else {
      project(A, bk, box.hard_lo, box.hard_hi, true);
      if (bounds.smooth) {
        // each joint approaches the feasible velocity, not the method's beyond the hard
        // limits: the approach toward an unreachable velocity held joints that the feasible
        // motion needs (an arm sliding along an obstacle crept at a few cm/s for seconds)
        aim_ = velocity - ff;
        joint_box(bounds, dt_, q, dq, aim_, ff, delta_, user_lo, user_hi, box);
        for (Index j = 0; j < n; ++j)
          if (box.torn[j]) status |= kConflict;
      }
    }
    for (Index j = 0; j < n; ++j) velocity[j] = std::min(std::max(velocity[j], box.lo[j]), box.hi[j]);
    const bool held_moved = bounds.smooth && hold_rows(A, bk);
    if (!feasible(velocity, A, bk, held_moved ? wide_lo_ : box.lo, held_moved ? wide_hi_ : box.hi)) {
      project(A, bk, box.lo, box.hi, false);
      bool broken = !rows_hold(A, bk);
      if (broken && bounds.smooth) {
        yield_smoothness(A, bk);
        for (Index j = 0; j < n; ++j)
          if (velocity[j] < box.cap_lo[j] - kBoundTol || velocity[j] > box.cap_hi[j] + kBoundTol) {
            box.torn[j] = 1;
            status |= kConflict;
          }
        broken = !rows_hold(A, bk);
      }
      if (broken) status |= kRowsBroken;
    }
    if (!report.converged) status |= kUnconverged;
  }
  if (replaced_ && goal_rows_ && !rested_ && !escaping)  // (an escape: see kRestRate)
    settle(J0, q, A, bk, user_lo, user_hi);
  if (!rested_) holding = velocity;
  rows_active.clear();
  for (Index i = 0; i < A.rows(); ++i)
    if (A.row(i).dot(holding) >= bk[i] - 1e-9 * (1.0 + std::abs(bk[i]))) rows_active.push_back(static_cast<int>(i));
  // where range_goal (lower_goal) replaced the first (lower) levels' feedback, the step is
  // reported against the method's own velocity: constrained, its share of the method's task
  // motion, and the limits that hold it (StepInfo compares the velocity with `desired`)
  if (lower_replaced_) {
    status |= kConstrained;
    kept = false;
    held_by_ranges(lgoal_, lgoal_lo_, lgoal_hi_);
    desired = method_desired_;
  }
  if (replaced_) {
    status |= kConstrained;
    kept = false;
    held_by_ranges(goal_, goal_lo_, goal_hi_);
    desired += method_top_ - desired_top;
    desired_top = method_top_;
  }
  // the share of level 0's task motion kept
  if (kept) {
    task_scale = 1.0;
  } else {
    tstar_.noalias() = J0 * desired_top;
    tmp2_.noalias() = J0 * velocity;
    const double asked = tstar_.squaredNorm();
    task_scale = asked > 0.0 ? std::clamp(tmp2_.dot(tstar_) / asked, 0.0, 1.0) : 1.0;
  }
  // 6. the displacement, exactly onto a limit it reaches (not a rounding past it); the state:
  // the velocity of the displacement made (where a step overran the room its range left, after
  // the rows made the limits yield, the next step's acceleration and jerk box started from the
  // velocity not made: on xArm7's stream beside a ball, under a variant of the braking bounds,
  // joint 2 stopped on its limit and took a jerk 1.14x its limit unreported)
  step = velocity * dt_;
  for (const PositionRange& r : bounds.ranges) {
    const double x = q[r.q];
    if (x >= r.lower && x <= r.upper) {
      const double cut = std::min(std::max(step[r.v], r.lower - x), r.upper - x);
      if (cut != step[r.v]) {
        step[r.v] = cut;
        velocity[r.v] = cut / dt_;
      }
    }
  }
  ddq = (velocity - dq) / dt_;
  dq = velocity;
  bent_.noalias() = J0 * dq;  // (trusted_share, next step)
  bent_ready_ = true;
  return status;
}

}  // namespace sjt
