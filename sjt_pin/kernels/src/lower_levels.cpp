// The levels below the first (controller.hpp): their step in the null space of the levels above,
// a posture's share of the self-motion, and their nearest feasible step where theirs is not.
#include "controller.hpp"

#include <algorithm>
#include <cmath>

namespace sjt {

namespace {

// a row of a lower level's projection whose part outside the rows above is below this share of
// their largest row's norm is spanned by them (the former eigen-decomposition's relative
// cutoff on the Gram matrix's eigenvalues, 1e-12, in singular values)
constexpr double kRankFloor = 1e-6;
// a posture's share of the self-motion (posture_share): 0 where the Gram matrix of the first
// level's target rows (of unit norm, over the joints free to move) has its least eigenvalue below
// kLockLow of its largest, 1 above kLockHigh, a smoothstep between (posture_share). Where a
// target is out of reach the arm rests at a singular configuration: its two nearly null
// directions were split anew each step, and the posture's velocity along the one called null
// swung sign from step to step (Panda, targets 1.5 m beyond reach, every method with a
// posture: +-2.5 rad/s at the speed limits for good, where without the posture the arm
// rests). Weighing the posture as a damped projector would (lambda^2 / (sigma^2 + lambda^2))
// left a posture pull along the nearly lost direction that DLS and SJT balanced and swung
// about. (1e-4: a least singular value 1 % of the largest.)
constexpr double kLockLow = 1e-6, kLockHigh = 1e-4;  // (posture_share)
// a row whose squared norm over the free joints is below this share of the largest is one they
// do not move (its rounding left): it counts as independent of the others (fade_posture)
constexpr double kStill = 1e-18;
// lower_nearest's weight of a posture's rows beside the tasks above it (the tasks' level comes
// first: with the posture's full weight, TALOS-like humanoids rested 1e-5 m short of a hand
// target, the posture pulling against the hand)
constexpr double kPostureShare = 1e-3;
// lower_nearest's weight of a motion no lower task sees: a share of the posture's mean weight
// (times kPostureShare), or without a posture of the task rows' mean squared column norm
constexpr double kInvisible = 1e-2;

}  // namespace

// Appends rows (k x nv, or the identity's when `rows` is null: every joint) to basis_, the
// orthonormal basis of the row space of the levels above (Gram-Schmidt, each row orthogonalised
// twice: "twice is enough", Giraud et al. 2005); a row whose part outside the basis is below
// kRankFloor of the largest row's norm is already spanned, and adds nothing.
void Controller::extend_basis(const RowMatrix* rows, Index begin, Index count) {
  for (Index i = 0; i < count && rank_ < nv; ++i) {
    auto w = basis_.col(rank_);
    if (rows) {
      w = rows->row(begin + i).transpose();
    } else {  // the identity's row i, on the moving joints
      w.setZero();
      w[i] = moving[i];
    }
    const double norm0 = w.norm();
    top_norm_ = std::max(top_norm_, norm0);
    if (!(norm0 > 0.0)) continue;
    for (int pass = 0; pass < 2; ++pass) {
      coef_.head(rank_).noalias() = basis_.leftCols(rank_).transpose() * w;
      w.noalias() -= basis_.leftCols(rank_) * coef_.head(rank_);
    }
    const double norm = w.norm();
    if (norm > kRankFloor * top_norm_) {
      w /= norm;
      ++rank_;
    }
  }
}

// v <- v minus its part in the row space of the levels above: v - Q Q^T v.
void Controller::null_project(Vector& v) {
  coef_.head(rank_).noalias() = basis_.leftCols(rank_).transpose() * v;
  v.noalias() -= basis_.leftCols(rank_) * coef_.head(rank_);
}

// A posture's share of the self-motion (kLockLow): the smoothstep of the least over the largest
// eigenvalue of the Gram matrix of the first level's target rows, each task's rows over its
// largest weight (rank_scale: a task weighted 1e-3 beside another loses no rank), over the
// joints not held at a position range's end by the first level's own velocity (at a
// constrained minimum against a range the joints left free are the singular ones; a joint the
// first level lets go the posture may pull off its end). A row the free joints do not move
// (kStill) counts as independent of the others (no motion changes it). Rows of unit norm
// instead hid a rank lost by a row that vanishes: Panda held by its joint 2 at its range below
// a target out of reach, its free joints' vertical row 1e-2 of the others, had a unit-row ratio
// of 2e-3 (the task's rows' 6e-7), and the posture swung joints 1 and 3 at their speed limits
// for good. The eigenvalues are computed only where a Cholesky factorisation of
// G - kLockHigh tr(G) I fails: elsewhere the least is above kLockHigh of the largest, and the
// share is 1.
double Controller::fade_posture(const double* q) {
  const Level& L0 = levels[0];
  const Index t = L0.targets;
  if (t == 0) return 1.0;
  lock_free_ = moving;
  const Vector& own = replaced_ ? method_top_ : desired_top;  // (desired_top: fb0_ + ff0_)
  for (const PositionRange& r : bounds.ranges) {
    const double x = q[r.q], v = own[r.v];
    if ((x >= r.upper && v > 0.0) || (x <= r.lower && v < 0.0)) lock_free_[r.v] = 0.0;
  }
  lock_rows_.noalias() = rank_scale.segment(L0.begin, t).asDiagonal() *
                         Jw_.middleRows(L0.begin, t) * lock_free_.asDiagonal();
  lock_gram_.noalias() = lock_rows_ * lock_rows_.transpose();
  const double top = lock_gram_.diagonal().maxCoeff();
  if (!(top > 0.0)) return 1.0;  // (no free joint moves the task: no motion disturbs it)
  for (Index i = 0; i < t; ++i)
    if (lock_gram_(i, i) <= kStill * top) lock_gram_(i, i) = top;
  const double trace = lock_gram_.trace();
  lock_shift_ = lock_gram_;
  lock_shift_.diagonal().array() -= kLockHigh * trace;
  lock_llt_.compute(lock_shift_);
  if (lock_llt_.info() == Eigen::Success) return 1.0;
  lock_eig_.compute(lock_gram_, Eigen::EigenvaluesOnly);
  const double least = std::max(lock_eig_.eigenvalues()[0], 0.0);
  const double most = std::max(lock_eig_.eigenvalues()[t - 1], 1e-300);
  const double x = std::clamp((least / most - kLockLow) / (kLockHigh - kLockLow), 0.0, 1.0);
  return x * x * (3.0 - 2.0 * x);
}

// x_fb, x_ff of the levels below the first, each in the null space of the rows above it
// (Siciliano and Slotine's recursion): a posture's velocity K w (q_ref - q) replaces the
// self-motion of the levels above, a task level solves its task velocity, less what the levels
// above already do to it, with the method's damped solve on its projected rows. The projector
// onto that null space, I - Q Q^T, comes from an orthonormal basis Q of the rows above, grown
// level by level (an eigen-decomposition of their Gram matrix per level was 61 % of this
// call's instructions on a humanoid with feet, hands and a posture).
//
// Without a feed-forward (no target velocity, no escape, no contact's drift: ff +0.0 on every
// joint) a level's feed-forward part is its solve of a zero task velocity, +-0.0 on every joint
// wherever its feedback part came out finite (the same factorisation, basis and share, none of
// them holding an inf or NaN), and +0.0 plus +-0.0 is +0.0: ff is left as it is, bitwise what
// the solve gives, without it (a third of this call on a humanoid with feet, hands and a
// posture). Where a feed-forward is asked, it reuses the feedback's factorisation.
void Controller::lower_levels(const double* ffw, const double* q) {
  const Level& top_level = levels[0];
  rank_ = 0;
  top_norm_ = 0.0;
  extend_basis(&Jw_, top_level.begin, top_level.end - top_level.begin);
  posture_share = has_posture_ ? fade_posture(q) : 1.0;
  const double lock = posture_share;
  const double gain = method.p.auto_gain ? method.p.gain_factor / dt_ : 1.0;
  bool no_ff = ffw == nullptr;
  for (Index j = 0; j < nv && no_ff; ++j) no_ff = ff[j] == 0.0 && !std::signbit(ff[j]);
  for (size_t index = 1; index < levels.size(); ++index) {
    const Level& level = levels[index];
    const Index rows = level.end - level.begin;
    if (rows == 0) continue;
    if (level.identity) {
      for (Index j = 0; j < nv; ++j) {
        const Index row = level.begin + j;
        tmp_[j] = gain * gains[row] * sqrt_weight[row] * ew_[row] - fb[j];
      }
      null_project(tmp_);
      fb += lock * tmp_;
      no_ff = no_ff && fb.allFinite();
      if (!no_ff) {
        tmp_ = -ff;
        null_project(tmp_);
        ff += lock * tmp_;
      }
      if (index + 1 < levels.size()) extend_basis(nullptr, 0, nv);
      continue;
    }
    // the level's rows projected: Jhat = J_k - (J_k Q) Q^T
    const auto Jk = Jw_.middleRows(level.begin, rows);
    coupling_.noalias() = Jk * basis_.leftCols(rank_);
    Jhat_ = Jk;
    Jhat_.noalias() -= coupling_ * basis_.leftCols(rank_).transpose();
    // a row the levels above span (to kRankFloor of its norm) is left with rounding only, which
    // a pseudo-inverse would blow up into a velocity: it asks nothing of this level
    for (Index i = 0; i < rows; ++i)
      if (Jhat_.row(i).norm() <= kRankFloor * Jk.row(i).norm()) Jhat_.row(i).setZero();
    lower_.prepare(Jhat_, ew_.segment(level.begin, rows), gains.segment(level.begin, rows),
                   level.targets, dt_, lower_step_);
    level_t_ = gain * gains.segment(level.begin, rows).cwiseProduct(ew_.segment(level.begin, rows));
    level_t_.noalias() -= Jk * fb;
    const bool pseudo = method.p.family == Family::least_squares && method.p.mu == 0.0;
    lower_.solve(Jhat_, level_t_, lower_step_.s, lower_step_.damping, pseudo, tmp_);
    null_project(tmp_);
    fb += tmp_;
    no_ff = no_ff && fb.allFinite();
    if (!no_ff) {
      if (ffw) level_t_ = ffw_.segment(level.begin, rows);
      else level_t_.setZero(rows);
      level_t_.noalias() -= Jk * ff;
      lower_.apply(Jhat_, level_t_, tmp_);  // (solve()'s factorisation, the same rows)
      null_project(tmp_);
      ff += tmp_;
    }
    if (index + 1 < levels.size()) extend_basis(&Jw_, level.begin, rows);
  }
}

// The lower levels' metric (lower_nearest): their task rows into low_B_ (weighted), a posture's
// diagonal times kPostureShare into low_p_; returns eps.
double Controller::lower_metric() {
  Index task_rows = 0;
  for (size_t index = 1; index < levels.size(); ++index)
    if (!levels[index].identity) task_rows += levels[index].end - levels[index].begin;
  low_B_.resize(task_rows, nv);
  low_p_.setZero(nv);
  Index at = 0;
  for (size_t index = 1; index < levels.size(); ++index) {
    const Level& level = levels[index];
    const Index rows = level.end - level.begin;
    if (level.identity) {
      for (Index j = 0; j < nv; ++j) low_p_[j] += Jw_(level.begin + j, j) * Jw_(level.begin + j, j);
    } else {
      low_B_.middleRows(at, rows) = Jw_.middleRows(level.begin, rows);
      at += rows;
    }
  }
  // (with a posture, its velocity is the lower step's part that no task above sees, and eps a
  // small share of its weight, so that it is not slowed; without, eps a share of the tasks')
  const double moving_joints = std::max(moving.sum(), 1.0);
  low_p_ *= kPostureShare;
  const double posture = low_p_.sum() / moving_joints;
  return std::max(kInvisible * (posture > 0.0 ? posture : low_B_.squaredNorm() / moving_joints),
                  1e-300);
}

// The lower levels' step where it is not feasible: the velocity nearest it in their own task
// metric, with level 0's task motion held (Siciliano and Slotine's priority within the limits):
//
//     min  eps |x - x0|^2 + |P (x - t)|^2 + |B (x - t)|^2   s.t. box, rows, J0 x = J0 x0
//
// t = x0 + their step (tmp_), B their task rows (weighted), P^2 the diagonal of a posture's
// identity rows (times kPostureShare), eps kInvisible of the posture's mean weight (times
// kPostureShare), or without a posture of the task rows' mean squared column norm. A task below
// the first level keeps as much of its task motion as the limits allow, other joints taking
// over where one is at its limit (a knee at its limit under a humanoid's reaching hand); a
// motion no lower task sees costs eps and stays as level 0 has it: the nearest velocity in
// joint space kept the step's motions no lower task sees (Solo-12's legs turned at 23 rad/s
// under held feet with its centre of mass at the support's edge, and never came to rest). The
// objective is the projection's, (x - x*)^T (D + B^T B) (x - x*), D = eps + P^2 per moving
// joint, with x* its unconstrained minimiser (Woodbury: x* = D^-1 h - D^-1 B^T
// (I + B D^-1 B^T)^-1 B D^-1 h, h = eps x0 + P^2 t + B^T B t).
ProjectionReport Controller::lower_nearest(const Eigen::Ref<const RowMatrix>& J0,
                                           const Vector& base,
                                           const Vector& target,
                                           const Eigen::Ref<const RowMatrix>& A,
                                           const Eigen::Ref<const Vector>& b, const Vector& lo,
                                           const Vector& hi, Vector& out) {
  const double eps = lower_metric();
  // h, then D^-1 h (0 where a joint is held: it stays at x0)
  low_h_ = eps * base + low_p_.cwiseProduct(target);
  low_r_.noalias() = low_B_ * target;
  low_h_.noalias() += low_B_.transpose() * low_r_;
  for (Index j = 0; j < nv; ++j) {
    const bool moves = moving[j] != 0.0 && eps + low_p_[j] > 0.0;
    low_d_[j] = moves ? eps + low_p_[j] : kInf;
    low_dh_[j] = moves ? low_h_[j] / low_d_[j] : 0.0;
    low_dinv_[j] = moves ? 1.0 / low_d_[j] : 0.0;
  }
  low_gram_.noalias() = low_B_ * low_dinv_.asDiagonal() * low_B_.transpose();
  low_gram_.diagonal().array() += 1.0;
  low_r_.noalias() = low_B_ * low_dh_;
  low_llt_.compute(low_gram_);
  low_r_ = low_llt_.solve(low_r_);
  anchor_.noalias() = low_B_.transpose() * low_r_;
  anchor_ = low_dh_ - low_dinv_.cwiseProduct(anchor_);
  for (Index j = 0; j < nv; ++j)
    if (low_dinv_[j] == 0.0) anchor_[j] = base[j];
  low_c_.noalias() = J0 * base;
  return projection_.solve(anchor_, low_d_, low_B_, lo, hi, A, b, J0, low_c_, out);
}

// Under acceleration limits each joint brakes toward its share of the displacement the whole
// feedback asks (fb / K), the lower levels' share included. Where that share takes a joint past
// its position range (a posture's self-motion running a joint into its range), the other
// joints' shares assume a self-motion the range forbids: the joint stopped at its range while
// the others went on, the task's error grew, the first level took it back and the posture
// pushed again. Panda and KUKA iiwa with a posture, one joint's range narrowed, a held target
// (8 draws each of tests/test_range_minimum.py's) under jerk limits: 13 of 16 runs still moved
// after 12 s, at 0.02-1.4 rad/s, reachable targets included. There the lower levels'
// displacement is instead the nearest one within the ranges (and the rows' room) in their own
// metric (lower_nearest's), the first level's displacement d0 = fb0 / K held:
//     min  eps |d - d0|^2 + |P (d - t)|^2 + |B (d - t)|^2
//     s.t. lower - q <= d <= upper - q,   A d <= room,   J0 d = J0 d0,
// t = fb / K, and the feedback becomes K d (a joint outside its range: as range_goal's box).
// Not where d0 itself leaves the box (range_goal could not bound it). True: it replaced.
bool Controller::lower_goal(const Eigen::Ref<const RowMatrix>& J0, const double* q, double K,
                            const Eigen::Ref<const RowMatrix>& A, bool rows) {
  bool crosses = false;
  for (const PositionRange& r : bounds.ranges) {
    if (moving[r.v] == 0.0) continue;
    const double x = q[r.q];
    // (range_goal's d0 lands on the bound, to rounding)
    if (leaves_range(r, x, fb0_[r.v] / K, 1e-12 * (1.0 + std::abs(x)))) return false;
    crosses = crosses || leaves_range(r, x, fb[r.v] / K);
  }
  const Index k = rows ? A.rows() : 0;
  for (Index i = 0; i < k; ++i) {
    if (!std::isfinite(goal_room_[i])) continue;
    const double slack = 1e-12 * (std::abs(goal_room_[i]) + A.row(i).cwiseAbs().dot(fb0_.cwiseAbs()) / K);
    if (A.row(i).dot(fb0_) / K > goal_room_[i] + slack) return false;  // (as the ranges')
    crosses = crosses || A.row(i).dot(fb) / K > goal_room_[i];
  }
  if (!crosses) return false;
  lgoal_base_ = fb0_ / K;
  lgoal_target_ = fb / K;
  range_box(q, lgoal_lo_, lgoal_hi_);
  lgoal_.resize(nv);
  const ProjectionReport r =
      k > 0 ? lower_nearest(J0, lgoal_base_, lgoal_target_, A, goal_room_, lgoal_lo_, lgoal_hi_,
                            lgoal_)
            : lower_nearest(J0, lgoal_base_, lgoal_target_, Bnone_, goal_room_.head(0),
                            lgoal_lo_, lgoal_hi_, lgoal_);
  if (!r.converged || !lgoal_.allFinite()) return false;
  method_desired_ = fb + ff;
  fb = K * lgoal_;
  return true;
}

}  // namespace sjt
