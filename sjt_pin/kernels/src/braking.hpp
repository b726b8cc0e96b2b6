// Jerk-limited braking of one joint: how far it travels to stop, and the fastest velocity this
// step after which it can still stop before a point (a position limit, or where the feedback
// sends it). Units: rad (or m), s.
#pragma once

namespace sjt {

// Distance to stop from velocity w with acceleration a0 along it (positive: still speeding up;
// w < 0: moving away, the travel until a0 > 0 has ramped out and the velocity it left is
// braked), braking at the acceleration limit A reached and left at the jerk limit J (J = inf:
// at once). Phases: ramp a0 down to 0 if positive; move the deceleration to A (or to the peak
// of a triangular profile); hold; ramp back to 0. Continuous and increasing in w and a0.
double stopping_distance(double w, double a0, double A, double J);

// The largest velocity x in [lo, hi] such that after moving at x for dt (acceleration
// (x - v) / dt) the joint can stop within `room` at limits A, J (x <= 0 can, unless with an
// acceleration toward the room that the jerk limit cannot ramp out in time); `lo` when none can
// (the joint is late: the hardest braking the box allows). Brent's method on
// the overshoot, to a relative 1e-12 of the bracket.
double largest_stoppable(double lo, double hi, double v, double room, double dt, double A,
                         double J);

// The largest velocity x >= v after which the acceleration (x - v) / dt can still ramp down to
// 0 at the jerk limit J before the velocity passes u >= v: x + ((x - v)/dt)^2 / (2 J) <= u,
// closed form (u itself when J is infinite).
double approach_top(double v, double u, double dt, double J);

}  // namespace sjt
