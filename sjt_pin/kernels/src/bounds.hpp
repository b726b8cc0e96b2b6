// Each joint's bounds on this step's velocity (rad/s or m/s) from the built-in limits, in two
// classes: hard (position, speed, a user's bounds) and smooth (acceleration, jerk, and the
// braking that lets each joint stop where the feedback sends it). Where the two contradict each
// other the hard box wins: the velocity is its point nearest the smooth box, and the joint is
// reported torn (StepInfo.limit_conflicts).
//
// With acceleration limits A (and jerk limits J), from the last commanded velocity v and
// acceleration a:
// - acceleration: |x - v| <= A dt; jerk: |x - v - a dt| <= J dt^2 (the jerk yields to the
//   acceleration limit where the two boxes are apart);
// - the speed limit can still be held: x + a+|a+| / (2 J) <= V, a+ = (x - v) / dt;
// - approach: toward the method's velocity u without passing it, x + a+^2 / (2 J) <= u;
// - feedback braking: the joint can still stop (within (1 - RESERVE) A and J) before the
//   displacement delta the feedback asks of it, relative to the feed-forward's velocity;
// - position limits: the joint can still stop (same reserve) before each limit, and never
//   passes it within the step; a joint outside its range returns at its recovery speed, ramped.
// Together they make a target reached monotonically and at rest: each joint follows a
// jerk-limited braking profile toward where the feedback sends it, within about 1.1-1.7 times
// the time-optimal (Ruckig's) duration, never above a limit.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "array.hpp"

namespace sjt {

// which limit set a bound (StepInfo.active_limits names them)
enum Reason : int8_t {
  kNone = 0,
  kPosition = 1,
  kVelocity = 2,
  kAcceleration = 3,
  kJerk = 4,
  kBraking = 5,  // the feedback's braking or approach (a smoothness bound)
  kUser = 6,     // a user limit's bounds
  kFixed = 7,    // a joint no task moves
};

struct PositionRange {
  Index q = 0, v = 0;  // index in q and in the velocity
  double lower = 0.0, upper = 0.0, recovery = 1.0;
};

// whether a displacement d from x takes a joint past its range r (by more than slack), further
// out than it is (a joint outside its range counts only where d takes it further out)
inline bool leaves_range(const PositionRange& r, double x, double d, double slack = 0.0) {
  return (x + d > r.upper + slack && d > 0.0) || (x + d < r.lower - slack && d < 0.0);
}

struct BoundsConfig {
  Index nv = 0;
  Vector speed;                        // (nv) inf: none
  std::vector<PositionRange> ranges;   // limited 1-DoF joints
  bool smooth = false;                 // acceleration limits given
  Vector acceleration, jerk;           // (nv) jerk inf: none
  Vector moving;                       // (nv) 1: a task moves the joint
  static constexpr double kReserve = 0.2;  // share of A and J a braking plan keeps in reserve
};

struct JointBox {
  Vector lo, hi;                            // the combined box
  Vector hard_lo, hard_hi, soft_lo, soft_hi;
  Vector cap_lo, cap_hi;                    // the acceleration/jerk box alone (no preference)
  Vector brake_lo, brake_hi;                // each position range's braking bound (inf: none)
  // each position range's braking at the whole acceleration and jerk limits (no reserve; inf:
  // none): the bound a yield of the limits keeps (widened; set by stopping_bounds)
  Vector stop_lo, stop_hi;
  std::vector<int8_t> lo_by, hi_by;         // Reason of each bound
  std::vector<uint8_t> torn;                // the hard box overrode the smooth one
  std::vector<uint8_t> jerk_apart;          // the jerk box lay outside the acceleration box
  Vector span;                              // the acceleration limit's own span A dt (0: none)
  std::vector<int8_t> soft_lo_by, soft_hi_by;
  void resize(Index n);
};

// What each joint can do this step (its acceleration and jerk box, and the speed it can still
// hold) into out.cap_lo/cap_hi: the first part of joint_box, which feedback_scale needs.
void capability(const BoundsConfig& config, double dt, const Vector& v, const Vector& a,
                JointBox& out);

// The box of this step (after capability()). q: the configuration; v: the last velocity; fb,
// ff: the method's feedback and feed-forward velocity; delta: the displacement the feedback asks
// of each joint (fb / K); user_lo/user_hi: a user's hard bounds (may be null).
void joint_box(const BoundsConfig& config, double dt, const double* q, const Vector& v,
               const Vector& fb, const Vector& ff, const Vector& delta, const double* user_lo,
               const double* user_hi, JointBox& out);

// Each position range's braking at the whole acceleration and jerk limits, without the reserve
// the step's own braking keeps (BoundsConfig::kReserve), into out.stop_lo/stop_hi: the fastest
// velocity toward each end after which the joint can still stop there (where none can, the
// hardest braking the limits allow; inf for a joint without a range, one outside its range,
// one no task moves). After joint_box; q, v as there. Computed only where the rows make the
// limits yield (widened): off that path it costs nothing.
void stopping_bounds(const BoundsConfig& config, double dt, const double* q, const Vector& v,
                     JointBox& out);

// [lo, hi] of joint j cut to its range's braking at the whole limits (stop_lo, stop_hi; after
// stopping_bounds), its nearer side where the two are apart.
inline void within_stopping(const JointBox& box, Index j, double& lo, double& hi) {
  hi = std::min(hi, std::max(box.stop_hi[j], lo));
  lo = std::max(lo, std::min(box.stop_lo[j], hi));
}

// Joint j's acceleration/jerk box widened s times about its centre, within the hard box (its
// nearer side where the two are apart) and within its range's braking at the whole limits
// (stop_lo, stop_hi; likewise); the hard box where the smooth one is unbounded. A box the
// jerk pinned to a point (jerk_apart: after a step the rows forced) widens by its
// acceleration limit's own span A dt for each unit of s beyond 1: a point widened s times is
// still a point (seed 8 of the random trees then went straight to the hard box, 140x). A yield
// spends the braking's reserve and no more: a speed toward a range's end that the joint cannot
// brake from in time meets the end at speed later (SO-101's elbow, a ball driven at its
// forearm at 0.5 m/s under Franka's limits: the rows made the limits yield 2.2x for 300 steps,
// the elbow ran on at 4 rad/s toward an end 0.5 rad away and stopped there in one step, 280
// times its acceleration limit).
inline void widened(const JointBox& box, Index j, double s, double& lo, double& hi) {
  const double c = 0.5 * (box.cap_lo[j] + box.cap_hi[j]);
  const double h = 0.5 * (box.cap_hi[j] - box.cap_lo[j]);
  lo = box.hard_lo[j];
  hi = box.hard_hi[j];
  if (std::isfinite(c) && std::isfinite(h)) {
    const double w = s * h + (box.jerk_apart[j] != 0 ? (s - 1.0) * box.span[j] : 0.0);
    lo = std::max(box.hard_lo[j], std::min(c - w, box.hard_hi[j]));
    hi = std::min(box.hard_hi[j], std::max(c + w, box.hard_lo[j]));
  }
  within_stopping(box, j, lo, hi);
}

// The least value of a . x over the box whose joint j spans [lo, hi] = bounds(j, lo, hi); a
// joint the row leaves out (a_j = 0) adds nothing, even where its box is unbounded.
template <class Bounds>
double least_over(const Eigen::Ref<const Vector>& a, Bounds&& bounds) {
  double least = 0.0;
  for (Index j = 0; j < a.size(); ++j) {
    if (a[j] == 0.0) continue;
    double lo, hi;
    bounds(j, lo, hi);
    least += a[j] > 0.0 ? a[j] * lo : a[j] * hi;
  }
  return least;
}

// The least s >= 1 (to a relative 1e-9) at which some velocity within the boxes widened s times
// (widened) meets the row a x <= b; inf where no widening does (the hard box cannot, or a
// joint the row needs has a box of zero width). Each row alone: over several rows, the largest
// is a lower bound of what they need together.
double least_widening(const JointBox& box, const Eigen::Ref<const Vector>& a, double b);

}  // namespace sjt
