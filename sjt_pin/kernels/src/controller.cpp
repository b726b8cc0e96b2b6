// One CLIK step after the tasks (controller.hpp): construction and the step's pipeline, run;
// the nearest feasible step in feasible_step.cpp, where the arm rests in least_squares_rest.cpp,
// the levels below the first in lower_levels.cpp.
#include "controller.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "lie.hpp"

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
  expected.setZero(levels[0].targets);
  for (Vector* v : {&desired, &fb, &ff, &velocity, &fb0_, &ff0_, &desired_top, &x0_, &xa_,
                    &tmp_, &tmp2_, &lam_low_, &low_p_, &low_h_, &low_d_, &low_dh_, &low_dinv_,
                    &anchor_, &coef_, &wide_lo_, &wide_hi_, &rest_, &holding})
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

void Controller::set_log6_rows(const Eigen::Matrix<int64_t, Eigen::Dynamic, 1>& rows) {
  const Level& L0 = levels[0];
  std::vector<Index> kept;
  for (Index k = 0; k < rows.size(); ++k) {
    if (rows[k] < L0.begin || rows[k] + 6 > L0.begin + L0.targets)
      fail("a pose error's rows must be 6 target rows of the first level");
    kept.push_back(static_cast<Index>(rows[k]));
  }
  log6_rows_ = kept;
  jlog6_.setZero(6, 6);
  exact6_.setZero(6, nv);
}

// The first level's pose errors e = log6(N) with their exact rows G J, G = Jlog6(N^-1), and
// their feed-forward G ff (the frame's twist that follows the target, in LOCAL axes: then
// e_dot = -G (J q_dot - ff) exactly), into `out` (run: Jw_, first = 0; first_rows: the first
// level's rows, first = its first row). The CLIK rows J give the error's rate only to first
// order near the target (the paper's Lyapunov argument for D J^T, eq. 22, takes
// e_dot = -J q_dot): far from it SE(3)'s logarithm couples the position rows with the
// rotation, and J^T e is not the error's gradient. run() takes these rows from a rest at a
// position range on (watch_rest), where the CLIK model can be stationary while the error still
// falls.
void Controller::exact_rows(const Eigen::Ref<const RowMatrix>& J,
                            const Eigen::Ref<const Vector>& e, const double* ff_in,
                            Eigen::Ref<RowMatrix> out, Index first) {
  for (const Index r : log6_rows_) {
    jlog6_inverse(e.data() + r, MatrixMap(jlog6_.data(), 6, 6));
    exact6_.noalias() = jlog6_ * J.middleRows(r, 6);
    out.middleRows(r - first, 6).noalias() =
        sqrt_weight.segment(r, 6).asDiagonal() * exact6_ * moving.asDiagonal();
    if (ff_in) {
      const Eigen::Map<const Eigen::Matrix<double, 6, 1>> f(ff_in + r);
      ffw_.segment(r, 6).noalias() =
          sqrt_weight.segment(r, 6).cwiseProduct(jlog6_ * f);
    }
  }
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
                    const Eigen::Ref<const Vector>& b, const double* room) {
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
  const auto hard = [this](Index j, double& lo, double& hi) {
    lo = box.hard_lo[j];
    hi = box.hard_hi[j];
  };
  for (Index i = 0; i < k; ++i) bk_[i] = std::max(b[i], least_over(A.row(i).transpose(), hard));
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
  bent_.noalias() = J0 * dq;  // (measured_bend, next step)
  bent_ready_ = true;
  if (!log6_rows_.empty()) watch_rest(status, q, step);
  return status;
}

// Whether the next steps take the pose errors' exact rows (exact_rows): from a rest held by a
// position range (the stage changed the method's step, a joint ends the step within
// kRangeTol of its range, and the step lowered 1/2 |e_w|^2 by less than kRestRate of it a
// second) kStillSteps steps long, short of the target, outside the saddle escape's watch (a
// stall of the method's own, which its curvature test answers in the CLIK model); until |e_w|
// is below kExactTo times the converged floor. (Not at a rest held by collision rows alone:
// there the arm slid on along the obstacle, xArm7 behind one resting at 7.8 s instead of 1.6.)
void Controller::watch_rest(int status, const double* q, const Eigen::Ref<const Vector>& step) {
  const Level& L0 = levels[0];
  const auto ew0 = ew_.segment(L0.begin, L0.targets);
  const double sq = ew0.squaredNorm();
  if (exact) {
    exact = sq >= kExactTo * kExactTo * stall_floor;
  } else {
    double rate = ew0.dot(bent_.head(L0.targets));
    if (ff_sq > 0.0) rate -= ew0.dot(ffw_.segment(L0.begin, L0.targets));
    bool resting = (status & kConstrained) && !escaping && stall_run < 0.0 &&
                   sq > kExactFrom * kExactFrom * stall_floor && std::abs(rate) < kRestRate * sq;
    if (resting) {
      bool at_range = false;
      for (const PositionRange& r : bounds.ranges) {
        const double x = q[r.q] + step[r.v];
        at_range = at_range || x <= r.lower + kRangeTol || x >= r.upper - kRangeTol;
      }
      resting = at_range;
    }
    still = resting ? still + 1.0 : 0.0;
    exact = still >= kStillSteps;
    if (exact) still = 0.0;
  }
  if (exact) {  // the error the next step expects of this one's motion (keeps_exact)
    expected = ew0 - dt_ * bent_.head(L0.targets);
    if (ff_sq > 0.0) expected += dt_ * ffw_.segment(L0.begin, L0.targets);
  }
}

// Whether this step takes the exact rows: those of a rest (watch_rest) belong to its target,
// and a new one (the first level's weighted error off the one the last step expects by more
// than kJump of itself: a target that jumped, not one that moves) starts again in the CLIK
// rows. (Kept for the next ones, the exact rows changed the basins of the targets that followed
// a rest: TALOS's arm and Z1 on the settle bench's streams, 6 fewer targets reached.)
bool Controller::keeps_exact(const Eigen::Ref<const Vector>& e) {
  if (!exact) return false;
  const Level& L0 = levels[0];
  double off = 0.0, size = 0.0;
  for (Index i = 0; i < L0.targets; ++i) {
    const double ew = sqrt_weight[L0.begin + i] * e[L0.begin + i];
    off += (ew - expected[i]) * (ew - expected[i]);
    size += ew * ew;
  }
  if (off > kJump * kJump * size) exact = false;
  return exact;
}

}  // namespace sjt
