// Each joint's box on this step's velocity (bounds.hpp).
#include "bounds.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "braking.hpp"

namespace sjt {

namespace {

constexpr double kBoundSlack = 1e-12;  // rad/s: a hard bound this close to the box is on it

inline void tighten_hi(double value, int8_t reason, double& hi, int8_t& by) {
  if (value < hi) {
    hi = value;
    by = reason;
  }
}
inline void tighten_lo(double value, int8_t reason, double& lo, int8_t& by) {
  if (value > lo) {
    lo = value;
    by = reason;
  }
}

}  // namespace

void JointBox::resize(Index n) {
  for (Vector* x : {&lo, &hi, &hard_lo, &hard_hi, &soft_lo, &soft_hi, &cap_lo, &cap_hi,
                    &brake_lo, &brake_hi, &stop_lo, &stop_hi})
    x->resize(n);
  span.setZero(n);
  lo_by.resize(n);
  hi_by.resize(n);
  torn.resize(n);
  jerk_apart.resize(n);
  soft_lo_by.resize(n);
  soft_hi_by.resize(n);
}

void capability(const BoundsConfig& config, double dt, const Vector& v, const Vector& a,
                JointBox& out) {
  const Index n = config.nv;
  out.resize(n);
  for (Index j = 0; j < n; ++j) {
    double sl = -kInf, sh = kInf;
    int8_t sl_by = kNone, sh_by = kNone;
    out.jerk_apart[j] = 0;
    out.span[j] = 0.0;
    if (config.smooth && config.moving[j] != 0.0) {
      const double A = config.acceleration[j], J = config.jerk[j];
      out.span[j] = A * dt;
      sl = v[j] - A * dt, sh = v[j] + A * dt;
      sl_by = sh_by = kAcceleration;
      if (std::isfinite(J)) {
        const double jl = v[j] + a[j] * dt - J * dt * dt, jh = v[j] + a[j] * dt + J * dt * dt;
        if (jh >= sl && jl <= sh) {
          tighten_lo(jl, kJerk, sl, sl_by);
          tighten_hi(jh, kJerk, sh, sh_by);
        } else {  // the jerk yields to the acceleration limit (after a step the rows forced):
          // the acceleration bound nearest the jerk box, the least jerk the limit allows
          out.jerk_apart[j] = 1;
          if (jh < sl) sh = sl, sh_by = kJerk;
          else sl = sh, sl_by = kJerk;
        }
        // the speed limit can still be held once the acceleration ramps down
        const double V = config.speed[j];
        if (std::isfinite(V)) {
          tighten_hi(std::max(sl, approach_top(v[j], std::max(V, v[j]), dt, J)), kJerk, sh,
                     sh_by);
          tighten_lo(std::min(sh, -approach_top(-v[j], std::max(V, -v[j]), dt, J)), kJerk, sl,
                     sl_by);
        }
      }
    }
    out.cap_lo[j] = sl, out.cap_hi[j] = sh;
    out.soft_lo_by[j] = sl_by, out.soft_hi_by[j] = sh_by;
  }
}

void joint_box(const BoundsConfig& config, double dt, const double* q, const Vector& v,
               const Vector& fb, const Vector& ff, const Vector& delta, const double* user_lo,
               const double* user_hi, JointBox& out) {
  const Index n = config.nv;
  std::vector<int8_t>& soft_lo_by = out.soft_lo_by;
  std::vector<int8_t>& soft_hi_by = out.soft_hi_by;
  const double keep = 1.0 - BoundsConfig::kReserve;
  for (Index j = 0; j < n; ++j) {
    double hl = -config.speed[j], hh = config.speed[j];
    int8_t hl_by = std::isfinite(hl) ? kVelocity : kNone, hh_by = hl_by;
    if (user_lo && user_lo[j] > hl) hl = user_lo[j], hl_by = kUser;
    if (user_hi && user_hi[j] < hh) hh = user_hi[j], hh_by = kUser;
    double sl = out.cap_lo[j], sh = out.cap_hi[j];
    int8_t sl_by = soft_lo_by[j], sh_by = soft_hi_by[j];
    if (config.smooth && config.moving[j] != 0.0) {
      const double A = config.acceleration[j], J = config.jerk[j];
      if (std::isfinite(J)) {  // approach the method's velocity without passing it
        const double u = fb[j] + ff[j];
        if (u > v[j]) tighten_hi(std::max(sl, approach_top(v[j], u, dt, J)), kBraking, sh, sh_by);
        if (u < v[j]) tighten_lo(std::min(sh, -approach_top(-v[j], -u, dt, J)), kBraking, sl, sl_by);
      }
      // brake the feedback so that the joint can stop where it sends it (relative to the
      // feed-forward's velocity)
      const double d = delta[j], f = ff[j];
      if (d > 0.0) {
        const double top = f + largest_stoppable(sl - f, sh - f, v[j] - f, d, dt, keep * A, keep * J);
        tighten_hi(std::max(sl, top), kBraking, sh, sh_by);
      } else if (d < 0.0) {
        const double top = f - largest_stoppable(f - sh, f - sl, f - v[j], -d, dt, keep * A, keep * J);
        tighten_lo(std::min(sh, top), kBraking, sl, sl_by);
      }
    }
    if (config.moving[j] == 0.0) {  // no task moves it: it stays
      hl = std::max(hl, 0.0), hh = std::min(hh, 0.0);
      hl_by = hh_by = kFixed;
    }
    out.hard_lo[j] = hl, out.hard_hi[j] = hh, out.soft_lo[j] = sl, out.soft_hi[j] = sh;
    out.lo_by[j] = hl_by, out.hi_by[j] = hh_by;
    soft_lo_by[j] = sl_by, soft_hi_by[j] = sh_by;
  }
  // position limits (hard), planned within the smooth box
  out.brake_lo.setConstant(-kInf);
  out.brake_hi.setConstant(kInf);
  for (const PositionRange& r : config.ranges) {
    const Index j = r.v;
    if (config.moving[j] == 0.0) continue;
    const double x = q[r.q];
    const double room_up = r.upper - x, room_down = x - r.lower;
    if (room_up < 0.0 || room_down < 0.0) {  // outside: back toward the range, ramped
      const bool above = room_up < 0.0;
      // without acceleration limits it lands on the range's edge; with them it enters the
      // range at the speed it has (stopping at the edge in one step broke the acceleration
      // limit 25x; inside, the range's own braking takes over)
      double back = config.smooth ? r.recovery
                                  : std::min(r.recovery, std::abs(above ? room_up : room_down) / dt);
      if (config.smooth) {
        const double toward = std::max(above ? -v[j] : v[j], 0.0);
        const double A = config.acceleration[j], J = config.jerk[j];
        back = std::min(back, approach_top(toward, std::max(back, toward), dt, J));
        back = std::min(back, toward + A * dt);
      }
      const double value = above ? -back : back;
      out.hard_lo[j] = out.hard_hi[j] = value;
      out.lo_by[j] = out.hi_by[j] = kPosition;
      continue;
    }
    double up = room_up / dt, down = room_down / dt;
    if (config.smooth) {  // within what the joint can do this step
      const double A = keep * config.acceleration[j], J = keep * config.jerk[j];
      double lo = std::max(out.cap_lo[j], out.hard_lo[j]), hi = std::min(out.cap_hi[j], out.hard_hi[j]);
      if (lo > hi) lo = out.cap_lo[j], hi = out.cap_hi[j];
      up = std::min(up, largest_stoppable(lo, hi, v[j], room_up, dt, A, J));
      down = std::min(down, largest_stoppable(-hi, -lo, -v[j], room_down, dt, A, J));
    }
    // (a braking bound no tighter than the smooth box is that box's, not the position's)
    up = std::max(up, 0.0), down = std::max(down, 0.0);
    out.brake_hi[j] = up, out.brake_lo[j] = -down;
    if (up < out.soft_hi[j]) tighten_hi(up, kPosition, out.hard_hi[j], out.hi_by[j]);
    if (-down > out.soft_lo[j]) tighten_lo(-down, kPosition, out.hard_lo[j], out.lo_by[j]);
  }
  // the combined box: the hard one wins where they are apart
  for (Index j = 0; j < n; ++j) {
    double lo = out.hard_lo[j], hi = out.hard_hi[j];
    int8_t lo_by = out.lo_by[j], hi_by = out.hi_by[j];
    tighten_lo(out.soft_lo[j], soft_lo_by[j], lo, lo_by);
    tighten_hi(out.soft_hi[j], soft_hi_by[j], hi, hi_by);
    const bool apart = lo > hi;
    // torn: the hard box leaves no velocity within the acceleration/jerk limits themselves (a
    // hard bound apart from the braking's preferences alone breaks no limit)
    const bool beyond = out.hard_lo[j] > out.cap_hi[j] + kBoundSlack ||
                        out.hard_hi[j] < out.cap_lo[j] - kBoundSlack;
    out.torn[j] = beyond || out.jerk_apart[j];
    if (apart) {
      const double near = std::min(std::max(out.soft_hi[j] < out.hard_lo[j] ? out.soft_hi[j]
                                                                             : out.soft_lo[j],
                                            out.hard_lo[j]),
                                   out.hard_hi[j]);
      lo = hi = near;
      lo_by = near == out.hard_lo[j] ? out.lo_by[j] : out.hi_by[j];
      hi_by = lo_by;
    }
    out.lo[j] = lo, out.hi[j] = hi, out.lo_by[j] = lo_by, out.hi_by[j] = hi_by;
  }
}

void stopping_bounds(const BoundsConfig& config, double dt, const double* q, const Vector& v,
                     JointBox& out) {
  out.stop_lo.setConstant(config.nv, -kInf);
  out.stop_hi.setConstant(config.nv, kInf);
  if (!config.smooth) return;
  for (const PositionRange& r : config.ranges) {
    const Index j = r.v;
    if (config.moving[j] == 0.0) continue;
    const double x = q[r.q], room_up = r.upper - x, room_down = x - r.lower;
    if (room_up < 0.0 || room_down < 0.0) continue;  // (outside: the hard box brings it back)
    const double A = config.acceleration[j], J = config.jerk[j];
    // (the velocities a widened box can hold: from the hardest braking the limits allow this
    // step to the speed limit)
    const double lo = std::min(out.cap_lo[j], 0.0), hi = std::max(out.hard_hi[j], lo);
    const double up = std::min(room_up / dt, largest_stoppable(lo, hi, v[j], room_up, dt, A, J));
    const double lo_down = std::min(-out.cap_hi[j], 0.0);
    const double hi_down = std::max(-out.hard_lo[j], lo_down);
    const double down =
        std::min(room_down / dt, largest_stoppable(lo_down, hi_down, -v[j], room_down, dt, A, J));
    out.stop_hi[j] = std::max(up, 0.0);
    out.stop_lo[j] = -std::max(down, 0.0);
  }
}

namespace {

// the least value of a x over the boxes widened s times
double least_value(const JointBox& box, const Eigen::Ref<const Vector>& a, double s) {
  return least_over(a, [&](Index j, double& lo, double& hi) { widened(box, j, s, lo, hi); });
}

}  // namespace

double least_widening(const JointBox& box, const Eigen::Ref<const Vector>& a, double b) {
  constexpr double kHuge = 1e300;  // (beyond it, the hard box)
  if (least_value(box, a, 1.0) <= b) return 1.0;
  if (!(least_value(box, a, kHuge) <= b)) return std::numeric_limits<double>::infinity();
  double low = 1.0, high = 2.0;  // (the least value falls as s grows: doubled, then bisected)
  while (high < kHuge && !(least_value(box, a, high) <= b)) {
    low = high;
    high *= 2.0;
  }
  while (high - low > 1e-9 * high) {
    const double s = 0.5 * (low + high);
    (least_value(box, a, s) <= b ? high : low) = s;
  }
  return high;
}

}  // namespace sjt

// -- Python entry, for the tests (tests/test_kernels.py checks it against a numpy search)
#include "registry.hpp"

namespace sjt {

void register_bounds(nb::module_& m) {
  m.def(
      "least_widening",
      [](nb::handle cap_lo, nb::handle cap_hi, nb::handle hard_lo, nb::handle hard_hi,
         nb::handle a, double b) {
        Array row(a, "a", 1);
        const Index n = row.size();
        row.finite();
        JointBox box;
        box.resize(n);
        box.stop_lo.setConstant(-kInf);  // (no range)
        box.stop_hi.setConstant(kInf);
        const std::pair<const char*, nb::handle> given[] = {
            {"cap_lo", cap_lo}, {"cap_hi", cap_hi}, {"hard_lo", hard_lo}, {"hard_hi", hard_hi}};
        Vector* into[] = {&box.cap_lo, &box.cap_hi, &box.hard_lo, &box.hard_hi};
        for (int i = 0; i < 4; ++i) {
          Array bound(given[i].second, given[i].first, 1);
          bound.length(n).no_nan();
          *into[i] = bound.vector();
        }
        if (std::isnan(b)) fail("least_widening: b is NaN");
        for (Index j = 0; j < n; ++j)
          if (box.cap_lo[j] > box.cap_hi[j] || box.hard_lo[j] > box.hard_hi[j])
            fail("least_widening: each box needs lo <= hi (cap_lo, cap_hi; hard_lo, hard_hi)");
        return least_widening(box, row.vector(), b);
      },
      nb::arg("cap_lo").none(), nb::arg("cap_hi").none(), nb::arg("hard_lo").none(),
      nb::arg("hard_hi").none(), nb::arg("a").none(), nb::arg("b"),
      "least_widening(cap_lo, cap_hi, hard_lo, hard_hi, a, b) -> float: the least s >= 1 at "
      "which some velocity within the acceleration/jerk box [cap_lo, cap_hi] widened s times "
      "about its centre, within the hard box [hard_lo, hard_hi], meets a x <= b (inf: no widening "
      "does).");
}

}  // namespace sjt
