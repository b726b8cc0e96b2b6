// Jerk-limited braking (braking.hpp).
#include "braking.hpp"

#include <algorithm>
#include <cmath>

namespace sjt {

double stopping_distance(double w, double a0, double A, double J) {
  if (w <= 0.0 && a0 <= 0.0) return 0.0;
  const bool jerk_limited = std::isfinite(J);
  const double inv_j = jerk_limited ? 1.0 / J : 0.0;
  const double jerk = jerk_limited ? J : 0.0;
  // still speeding up: ramp a0 down to 0 first
  const double up = std::max(a0, 0.0), t0 = up * inv_j;
  const double d0 = w * t0 + up * t0 * t0 / 3.0;
  w += 0.5 * up * up * inv_j;
  const double beta = std::max(-a0, 0.0);  // already braking at beta
  if (w <= 0.0) return d0;
  if (!jerk_limited) return d0 + w * w / (2.0 * A);
  if (beta * beta >= 2.0 * jerk * w) {  // more deceleration than needed: stops while it ramps down
    const double ts = (beta - std::sqrt(std::max(beta * beta - 2.0 * jerk * w, 0.0))) * inv_j;
    return d0 + w * ts - 0.5 * beta * ts * ts + jerk * ts * ts * ts / 6.0;
  }
  const double sign = beta > A ? 1.0 : -1.0;
  const double t1 = std::abs(A - beta) * inv_j;
  const double v1 = w - beta * t1 + 0.5 * sign * jerk * t1 * t1;
  const double v2 = 0.5 * A * A * inv_j;
  if (v1 >= v2) {  // trapezoid: beta to A, hold A, ramp A to 0
    const double d1 = w * t1 - 0.5 * beta * t1 * t1 + sign * jerk * t1 * t1 * t1 / 6.0;
    const double t2 = (v1 - v2) / A;
    return d0 + d1 + v1 * t2 - 0.5 * A * t2 * t2 + A * A * A * inv_j * inv_j / 6.0;
  }
  // triangle: peak a_p with (a_p^2 - beta^2) / 2J + a_p^2 / 2J = w, then back to 0
  const double a_p = std::sqrt(std::max(w * jerk + 0.5 * beta * beta, 0.0));
  const double ta = (a_p - beta) * inv_j;
  return d0 + w * ta - 0.5 * beta * ta * ta - jerk * ta * ta * ta / 6.0 +
         a_p * a_p * a_p * inv_j * inv_j / 6.0;
}

namespace {

// > 0 where velocity x (after this step) cannot stop within room. A velocity away from the
// room fits, but not with an acceleration toward it that the jerk limit cannot take back in
// time: reversing from -0.076 rad/s at 6.5 rad/s^2 with a jerk limit of 78 rad/s^3 (the
// acceleration needs 83 ms to ramp down, and gains 0.27 rad/s meanwhile), UR5's wrist passed
// a goal 4 mrad ahead by 20 mrad, and swung about it for seconds. (J finite: without a jerk
// limit largest_stoppable solves in closed form.)
double overshoot(double x, double v, double room, double dt, double A, double J) {
  const double a0 = (x - v) / dt;
  if (x <= 0.0 && a0 <= 0.0) return -1.0;
  return x * dt + stopping_distance(x, a0, A, J) - room;
}

}  // namespace

double largest_stoppable(double lo, double hi, double v, double room, double dt, double A,
                         double J) {
  if (!(A > 0.0) || !std::isfinite(A)) return hi;
  room = std::max(room, 0.0);
  if (!std::isfinite(J)) {  // closed form: x dt + x^2 / (2 A) = room
    const double x = A * (std::sqrt(dt * dt + 2.0 * room / A) - dt);
    return std::min(std::max(x, lo), hi);
  }
  double f_hi = overshoot(hi, v, room, dt, A, J);
  if (f_hi <= 0.0) return hi;
  double f_lo = overshoot(lo, v, room, dt, A, J);
  if (f_lo > 0.0) return lo;
  // (0 fits where it needs no acceleration toward the room, and the overshoot may jump just
  // above it: the bracket then starts at 0)
  if (lo < 0.0 && 0.0 < hi && overshoot(0.0, v, room, dt, A, J) <= 0.0) {
    lo = 0.0;
    f_lo = -1.0;
  }
  // Brent's safeguards (1973) on the bracket [lo, hi], f(lo) <= 0 < f(hi): inverse quadratic
  // interpolation through the last three points (a secant step while there are two), and a
  // bisection wherever that lands outside the bracket or the bracket did not halve over the
  // last two steps. The overshoot is piecewise polynomial with square roots: regula falsi
  // (Illinois) took up to 53 evaluations a call here.
  const double tol = 1e-12 * (hi - lo + 1e-300);
  double c = lo, f_c = f_lo;  // the end the bracket's last move dropped
  double width[2] = {hi - lo, hi - lo};  // the bracket one and two steps ago (the first step bisects)
  for (int k = 0; k < 100 && hi - lo > tol; ++k) {
    double x;
    if (f_c != f_lo && f_c != f_hi) {
      x = lo * f_hi * f_c / ((f_lo - f_hi) * (f_lo - f_c)) +
          hi * f_lo * f_c / ((f_hi - f_lo) * (f_hi - f_c)) +
          c * f_lo * f_hi / ((f_c - f_lo) * (f_c - f_hi));
    } else {
      x = lo - f_lo * (hi - lo) / (f_hi - f_lo);
    }
    if (!(x > lo && x < hi) || hi - lo > 0.5 * width[1]) x = 0.5 * (lo + hi);
    // (a quarter of the tolerance from either end at least: the bracket always shrinks)
    x = std::min(std::max(x, lo + 0.25 * tol), hi - 0.25 * tol);
    width[1] = width[0];
    width[0] = hi - lo;
    const double fx = overshoot(x, v, room, dt, A, J);
    if (fx <= 0.0) {
      c = lo, f_c = f_lo;
      lo = x, f_lo = fx;
    } else {
      c = hi, f_c = f_hi;
      hi = x, f_hi = fx;
    }
  }
  return lo;
}

double approach_top(double v, double u, double dt, double J) {
  if (!std::isfinite(J)) return u;
  const double c = J * dt * dt;
  return v + c * (std::sqrt(1.0 + 2.0 * std::max(u - v, 0.0) / c) - 1.0);
}

}  // namespace sjt

// -- Python entries, for the tests (tests/test_braking.py checks them against Ruckig and numpy)
#include <nanobind/nanobind.h>

#include "registry.hpp"

namespace sjt {

void register_braking(nanobind::module_& m) {
  m.def("stopping_distance", &stopping_distance, nanobind::arg("w"), nanobind::arg("a0"),
        nanobind::arg("A"), nanobind::arg("J"),
        "stopping_distance(w, a0, A, J) -> float: distance (rad, m) to stop from velocity w with "
        "acceleration a0, at acceleration limit A and jerk limit J (inf: none).");
  m.def("largest_stoppable", &largest_stoppable, nanobind::arg("lo"), nanobind::arg("hi"),
        nanobind::arg("v"), nanobind::arg("room"), nanobind::arg("dt"), nanobind::arg("A"),
        nanobind::arg("J"),
        "largest_stoppable(lo, hi, v, room, dt, A, J) -> float: the fastest velocity in "
        "[lo, hi] after which a stop within room fits.");
  m.def("approach_top", &approach_top, nanobind::arg("v"), nanobind::arg("u"),
        nanobind::arg("dt"), nanobind::arg("J"),
        "approach_top(v, u, dt, J) -> float: the fastest velocity toward u that does not pass it.");
}

}  // namespace sjt
