// One CLIK step after the tasks (controller.hpp): construction and the step's pipeline, run;
// the nearest feasible step in feasible_step.cpp, where the arm rests in least_squares_rest.cpp,
// a pose error's exact rows in exact_rows.cpp, the levels below the first in lower_levels.cpp.
#include "controller.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace sjt {

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
  rest_keep.setZero(nv * nv);
  expected.setZero(levels[0].targets);
  for (Vector* v : {&desired, &fb, &ff, &velocity, &fb0_, &ff0_, &desired_top, &x0_, &xa_,
                    &tmp_, &tmp2_, &lam_low_, &low_p_, &low_h_, &low_d_, &low_dh_, &low_dinv_,
                    &anchor_, &coef_, &wide_lo_, &wide_hi_, &rest_, &rest_coef_, &holding,
                    &goal_desired_})
    v->setZero(nv);
  basis_.setZero(nv, nv);
  const Index r0 = levels[0].end - levels[0].begin;
  loop_.setZero(r0, r0);
  user_matrix.setZero(nv, r0);
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
  resting = false;
  start_error = 1e300;
  start_run = false;
  least_e_sq = 1e300;
  least_age = 0.0;
  pushed = false;
  forget_damping();
  nearest.forget();
  bent_ready_ = false;
  exact = false;
  still = 0.0;
}

void Controller::first_rows(const Eigen::Ref<const RowMatrix>& J,
                            const Eigen::Ref<const Vector>& e, double* rows) {
  const Level& L0 = levels[0];
  const Index r0 = L0.end - L0.begin;
  // (run()'s Jw_: the same products, entry by entry)
  Eigen::Map<RowMatrix> out(rows, r0, nv);
  out.noalias() = sqrt_weight.segment(L0.begin, r0).asDiagonal() * J.middleRows(L0.begin, r0) *
                  moving.asDiagonal();
  if (keeps_exact(e)) exact_rows(J, e, nullptr, out, L0.begin);
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

int Controller::run(const Eigen::Ref<const RowMatrix>& J, const Eigen::Ref<const Vector>& e,
                    const double* ff_in, const double* q, Eigen::Ref<Vector> step,
                    const double* matrix, const double* user_lo,
                    const double* user_hi, const Eigen::Ref<const RowMatrix>& A,
                    const Eigen::Ref<const Vector>& b, const double* room,
                    const double* needs, const double* dampers) {
  const Index n = nv;
  // 1. the weighted rows of the moving joints
  Jw_.noalias() = sqrt_weight.asDiagonal() * J * moving.asDiagonal();
  ew_ = sqrt_weight.cwiseProduct(e);
  bend_ = -1.0;
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
  exact_step = keeps_exact(e);
  if (exact_step) exact_rows(J, e, ff_in, Jw_, 0);
  // 2. the first level's method
  const Level& L0 = levels[0];
  const Index r0 = L0.end - L0.begin;
  const auto J0 = Jw_.middleRows(L0.begin, r0);
  // (a user's matrix: map_matrix takes the gain and its bound from J0 M, not the method's)
  method.prepare(J0, ew_.segment(L0.begin, r0), gains.segment(L0.begin, r0), L0.targets, dt_, top,
                 matrix == nullptr);
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
  if (stall_run < 0.0) resting = false;
  // at a minimum the curvature test found, the method's own feedback would creep on along its
  // flat directions, lowering the error by nothing measurable: xArm7 beyond reach (SJT, JT) at
  // 3e-4 rad/s after 30 s, |e| falling by 1e-10 of itself a second. Along them it rests while
  // the stall lasts; along the others it settles (the target's motion, the lower levels and
  // the escape go on)
  if (resting && !escaping) rest_along_flat();
  if (escaping) ff0_ += escape_velocity;
  // under acceleration limits, a first-level displacement past a position range gives way to
  // the bounded least-squares one (range_goal; the method's own velocity stays in method_top_)
  const Index counted = L0.targets > 0 ? L0.targets : r0;
  const double K = matrix ? given_gain
                          : (counted > 0 ? gains.segment(L0.begin, counted).mean() : 0.0) *
                                top.gain;
  replaced_ = bounds.smooth && K > 0.0 && range_goal(J0, q, K, matrix != nullptr, A, b, room,
                                                               dampers);
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
  // an obstacle, an obstacle faster than the speed limits) asks what the box allows at best,
  // and with acceleration limits what their box allows (yielding them would not keep it
  // either), as does a row its limit gives up (needs below b). Kept alone, it does not tear
  // the others apart (StepInfo.rows_exceeded reports a row as its limit needs it)
  const Index k = A.rows();
  bk_.resize(k);
  const auto hard = [this](Index j, double& lo, double& hi) {
    lo = box.hard_lo[j];
    hi = box.hard_hi[j];
  };
  const auto smooth = [this](Index j, double& lo, double& hi) {
    lo = std::min(box.lo[j], box.hi[j]);
    hi = std::max(box.lo[j], box.hi[j]);
  };
  for (Index i = 0; i < k; ++i) {
    const double best = least_over(A.row(i).transpose(), hard);
    bk_[i] = std::max(b[i], best);
    if (bounds.smooth && (b[i] < best || (needs != nullptr && needs[i] < b[i])))
      bk_[i] = std::max(bk_[i], least_over(A.row(i).transpose(), smooth));
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
  // Where a row's room binds range_goal's displacement and the target holds still (no
  // feed-forward), the velocity goes from the last one (its nearest point in the box)
  // straight toward the goal's, as far as every joint's box allows: the joints keep the
  // goal's proportions and the task moves along the goal's motion. Each joint clipped into its
  // own box went toward its own share at its own acceleration, from rest a sign vector of the
  // joints that moved the hand sideways: Panda (SJT) sent through a user's two floors under
  // jerk limits 500 and 2,000 times its acceleration limits rested 22 and 51 mm above them,
  // xArm7 14 mm (tests/test_rows_with_room.py). Not where the target moves: tracking a line
  // past a ball, the arm then rested against it (a local minimum of the goal, as every method
  // without acceleration limits rests there) where clipped joints slid out of it
  synced_ = replaced_ && goal_rows_ && ff_sq == 0.0;
  if (synced_) {
    // the goal's velocity no faster than the line can brake from within the goal's
    // displacement: sqrt(2 a |delta|), a the line's acceleration (the least A_j |fb| / |fb_j|)
    // less the reserve. Without it UR5 sent through a user's floors under jerk limits swung
    // +-2.5 mm about them along the line, each joint braking alone
    const double g = delta_.norm(), f = fb.norm();
    if (g > 0.0 && f > 0.0) {
      double a_line = kInf;
      for (Index j = 0; j < n; ++j)
        if (fb[j] != 0.0) a_line = std::min(a_line, bounds.acceleration[j] * f / std::abs(fb[j]));
      const double s_max = std::sqrt(2.0 * (1.0 - BoundsConfig::kReserve) * a_line * g);
      if (f > s_max) desired = (s_max / f) * fb;  // (ff is zero here)
    }
    double t = 1.0;
    for (Index j = 0; j < n; ++j) {
      const double lo = std::min(box.lo[j], box.hi[j]), hi = std::max(box.lo[j], box.hi[j]);
      const double p0 = std::clamp(dq[j], lo, hi);
      tmp_[j] = p0;
      const double d = desired[j] - p0;
      if (d > 0.0 && std::isfinite(hi)) t = std::min(t, std::max(hi - p0, 0.0) / d);
      if (d < 0.0 && std::isfinite(lo)) t = std::min(t, std::min(lo - p0, 0.0) / d);
    }
    goal_desired_ = desired;  // (settle's aim, and what the step is reported against)
    desired = tmp_ + t * (desired - tmp_);
  }
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
        stopping_bounds(bounds, dt_, q, dq, box);
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
  if (synced_) desired = goal_desired_;
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
  // (a row that pushes an arm at rest, below)
  const bool from_rest = !pushed && A.rows() > 0 && bounds.smooth && at_rest();
  ddq = (velocity - dq) / dt_;
  dq = velocity;
  bent_.noalias() = J0 * dq;  // (measured_bend, next step)
  bent_ready_ = true;
  // The error's record does not judge a motion a row forced: pushed out of the margin from
  // rest (a start inside it), the arm moves away from its target and brakes, and from the
  // rest that follows, the line was judged against the error before the push and braked at
  // once: Panda (SJT and DLS, jerk limits 500 times its acceleration limits) started 2.9 mm
  // inside a table's margin, rested at the margin 54 ms later at an error of 0.3076 and never
  // moved again, where the constrained minimum along the table is 0.3029. The record follows
  // the error from such a push as long as the arm's motion raises the first level's error,
  // and starts there. (Only from rest: a row that an arm sliding along an obstacle dips
  // into, by a fraction of a millimetre, reset the record again and again, and xArm7 slid
  // along a table for good, as without the window. Only a row the step moves away along: a
  // link no joint moves away, inside the margin for good, reset it at every rest, and Kinova
  // still moved after 8 s.)
  for (Index i = 0; i < A.rows() && from_rest && !pushed; ++i)
    pushed = b[i] < 0.0 && A.row(i).dot(dq) < -kPushed;
  const bool target_moved = e_sq > kRecord * least_e_sq;
  follow_damping(target_moved);  // (settle.cpp)
  if (pushed || e_sq < least_e_sq || target_moved) {
    least_e_sq = e_sq;
    least_age = 0.0;
  } else {
    least_age += dt_;
  }
  if (pushed && ew_.segment(L0.begin, r0).dot(bent_) >= 0.0) pushed = false;
  if (!log6_rows_.empty()) watch_rest(status, q, step);
  return status;
}

}  // namespace sjt
