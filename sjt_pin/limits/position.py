"""Joint position limits, approached with a speed that can still stop in time."""

from __future__ import annotations

import numpy as np

from .. import kernels
from .base import Limit, Motion

#: the share of the acceleration and jerk limits that a braking plan keeps in reserve
BRAKING_RESERVE = 0.2


class PositionLimit(Limit):
    """The URDF position limits of 1-DoF joints (revolute, prismatic) are never crossed.

    Bounds each limited joint's velocity so that the step ends inside the range,
    ``q_dot <= (upper - q) / dt``, and — when the solver has acceleration (and jerk) limits —
    so that the joint can still stop before the limit: ``q_dot dt + s(q_dot) <= upper - q``
    with the exact distance ``s`` of a braking at the acceleration limit reached and left at the
    jerk limit, from this step's velocity and acceleration (:func:`stopping_distance`; with the
    joint still accelerating toward the limit, ramping that acceleration down is counted too),
    planned with :data:`BRAKING_RESERVE` of the limits in reserve. A joint approaching its limit
    thus brakes in time; it never stops in one step. A joint that starts outside its range
    (a start configuration out of range) returns at ``recovery_speeds`` (rad/s or m/s), never
    jumps: with acceleration (and jerk) limits its speed back ramps up within them.

    Args:
        robot: where the limits come from (``robot.lower_limits``, ``upper_limits``).
        moving: (nv,) 1 for the joints the solver moves; the others are not bounded.
        recovery_speeds: (nv,) speed at which a joint outside its range returns (rad/s, m/s).
        acceleration: (nv,) acceleration limits (rad/s^2, m/s^2; ``inf`` for none), or ``None``.
        jerk: (nv,) jerk limits (rad/s^3, m/s^3; ``inf`` for none), or ``None``.
    """

    name = "position"

    def __init__(self, robot, moving: np.ndarray, recovery_speeds: np.ndarray,
                 acceleration: np.ndarray | None = None, jerk: np.ndarray | None = None):
        model = robot.model
        lower, upper = robot.lower_limits, robot.upper_limits
        qi, vi = [], []
        for j in range(1, model.njoints):
            joint = model.joints[j]
            if (joint.nq == 1 and joint.nv == 1 and moving[joint.idx_v]
                    and np.isfinite(lower[joint.idx_q]) and np.isfinite(upper[joint.idx_q])):
                qi.append(joint.idx_q)
                vi.append(joint.idx_v)
        self.nv = model.nv
        self.q_index = np.array(qi, dtype=np.int64)
        self.v_index = np.array(vi, dtype=np.int64)
        self.lower = lower[self.q_index].copy()
        self.upper = upper[self.q_index].copy()
        self.recovery_speeds = np.asarray(recovery_speeds, dtype=float)[self.v_index]
        self.acceleration = (None if acceleration is None
                             else np.asarray(acceleration, dtype=float)[self.v_index])
        self.jerk = None if jerk is None else np.asarray(jerk, dtype=float)[self.v_index]
        # the braking plans with a reserve of the limits (BRAKING_RESERVE), which the other
        # joints' coupling through the task may take from a step
        self._braking = (None if self.acceleration is None
                         else (1.0 - BRAKING_RESERVE) * self.acceleration,
                         None if self.jerk is None else (1.0 - BRAKING_RESERVE) * self.jerk)

    @property
    def active(self) -> bool:
        """Whether any moving joint has position limits."""
        return self.q_index.size > 0

    def bounds(self, kinematics, motion: Motion):
        if not self.active:
            return None
        dt = motion.dt
        x = motion.q[self.q_index]
        v, a = motion.dq[self.v_index], motion.ddq[self.v_index]
        room_up, room_down = self.upper - x, x - self.lower
        A, J = self._braking
        upper = np.minimum(braking_speed(room_up, v, a, dt, A, J),
                           room_up / dt)
        lower = -np.minimum(braking_speed(room_down, -v, -a, dt, A, J),
                            room_down / dt)
        # outside the range: back toward it at the recovery speed, no further than the limit
        above, below = room_up < 0, room_down < 0
        back = np.minimum(self.recovery_speeds, np.abs(np.where(above, room_up, room_down)) / dt)
        if self.acceleration is not None and (above.any() or below.any()):
            # turn back no harder than the acceleration (and jerk) limits allow (with the
            # braking's reserve): from the velocity toward the range, a ramp up to the
            # recovery speed, not a jump; and into the range without braking at its edge
            # (inside, the far limit bounds it)
            A, J = self._braking
            assert A is not None  # set with the acceleration limits
            toward = np.where(above, -v, v)
            cap = np.minimum(self.recovery_speeds, np.where(above, room_down, room_up) / dt)
            push = A
            if J is not None:  # the acceleration ramps, and ramps down before the cap
                gap = np.maximum(cap - toward, 0.0)
                with np.errstate(invalid="ignore"):  # a joint without a jerk limit: A
                    ramp = np.minimum(np.minimum(A, np.maximum(np.where(above, -a, a), 0.0)
                                                 + J * dt),
                                      np.sqrt((0.5 * J * dt) ** 2 + 2.0 * J * gap)
                                      - 0.5 * J * dt)
                push = np.where(np.isfinite(J), ramp, A)
            back = np.minimum(cap, toward + push * dt)
        lower = np.where(above, -back, np.where(below, back, lower))
        upper = np.where(above, -back, np.where(below, back, upper))
        lo, hi = np.full(self.nv, -np.inf), np.full(self.nv, np.inf)
        lo[self.v_index], hi[self.v_index] = lower, upper
        return lo, hi


def stopping_distance(w: np.ndarray, a0: np.ndarray, A: np.ndarray, J: np.ndarray
                      ) -> np.ndarray:
    """Distance (rad or m) to stop from velocity ``w > 0`` with acceleration ``a0`` along it
    (positive: still speeding up), braking at the acceleration limit ``A`` reached and left
    at the jerk limit ``J`` (``inf``: instantly). Phases: ramp ``a0`` down to 0 if positive;
    move the deceleration ``beta = -a0`` to ``A`` (up at ``J``, or down at ``J`` when it is
    beyond ``A``) or to the peak of a triangular profile when ``A`` is not reached; hold it;
    ramp back to 0. When the deceleration is already more than the velocity needs
    (``beta^2 >= 2 J w``), the joint stops while it ramps down, after ``t`` with
    ``w - beta t + J t^2 / 2 = 0``. Continuous and increasing in ``w`` and ``a0``."""
    finite = np.isfinite(J)
    inv_j = np.where(finite, 1.0 / np.where(finite, J, 1.0), 0.0)
    jerk = np.where(finite, J, 0.0)
    up = np.maximum(a0, 0.0)  # speeding up: ramp a0 down to 0 first
    t0 = up * inv_j
    d0 = w * t0 + up * t0 * t0 / 3.0
    w = w + 0.5 * up * up * inv_j
    beta = np.maximum(-a0, 0.0)  # already braking at beta
    # trapezoid: move beta to A (jerk -J up to it, +J down to it), hold A, ramp A -> 0
    sign = np.where(beta > A, 1.0, -1.0)
    t1 = np.abs(A - beta) * inv_j
    d1 = w * t1 - 0.5 * beta * t1 * t1 + sign * jerk * t1 * t1 * t1 / 6.0
    v1 = w - beta * t1 + 0.5 * sign * jerk * t1 * t1
    v2 = 0.5 * A * A * inv_j
    t2 = np.maximum(v1 - v2, 0.0) / A
    trapezoid = d1 + v1 * t2 - 0.5 * A * t2 * t2 + A * A * A * inv_j * inv_j / 6.0
    # triangle: peak a_p with (a_p^2 - beta^2) / 2J + a_p^2 / 2J = w, then back to 0
    a_p = np.sqrt(np.maximum(w * jerk + 0.5 * beta * beta, 0.0))
    ta = (a_p - beta) * inv_j
    triangle = (w * ta - 0.5 * beta * ta * ta - jerk * ta * ta * ta / 6.0
                + a_p * a_p * a_p * inv_j * inv_j / 6.0)
    # more deceleration than needed: the velocity reaches 0 while it ramps down
    ts = (beta - np.sqrt(np.maximum(beta * beta - 2.0 * jerk * w, 0.0))) * inv_j
    over = w * ts - 0.5 * beta * ts * ts + jerk * ts * ts * ts / 6.0
    return d0 + np.where(beta * beta >= 2.0 * jerk * w, over,
                         np.where(v1 >= v2, trapezoid, triangle))


#: the braking speed's root is found to this fraction of its bracket (that of 40 halvings)
BRAKING_TOL = kernels.BRAKING_TOL  # 2^-40
#: at most this many steps of the root search (it takes 5-15)
BRAKING_STEPS = kernels.BRAKING_STEPS


def _overshoot(x, v, room, dt, A, J):
    """``x dt + stopping_distance(x, (x - v) / dt) - room``: > 0 where a velocity ``x`` toward
    a point ``room`` away cannot stop before it."""
    positive = np.maximum(x, 0.0)
    return x * dt + np.where(x > 0, stopping_distance(positive, (x - v) / dt, A, J),
                             0.0) - room


def braking_speed(room: np.ndarray, v: np.ndarray, a: np.ndarray, dt: float,
                  acceleration: np.ndarray | None, jerk: np.ndarray | None) -> np.ndarray:
    """The largest velocity x toward a point ``room`` away (rad or m: a position limit, or the
    rest of the way to a target) after which a joint can still stop before it within the
    ``acceleration`` and ``jerk`` limits (``inf`` without an acceleration limit); ``v`` is its
    previous velocity toward that point (rad/s), so this step's acceleration is
    ``(x - v) / dt`` (``a``, the previous acceleration, is not needed).

    Without a jerk limit it is the closed form of ``x dt + x^2 / (2 A) <= room``. With one, the
    overshoot ``x dt + stopping_distance(x, (x - v) / dt) - room`` grows with x (continuously
    for x > 0; at 0 it may jump up, when the joint must first stop speeding up): its root is
    found between ``v - 2 A dt`` and ``v + 2 A dt`` (what one step can reach) by regula falsi
    with the Illinois modification (a bisection step when it leaves the bracket), to
    :data:`BRAKING_TOL` of that bracket — the compiled kernel runs the same search.
    """
    if acceleration is None:
        return np.full(np.shape(room), np.inf)
    A = acceleration
    room = np.maximum(room, 0.0)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        if jerk is None:
            speed = A * (-dt + np.sqrt(dt * dt + 2.0 * room / A))
            return np.where(np.isfinite(A), speed, np.inf)
        J = jerk
        # only joints within the distance a stop from the highest speed one step can reach
        # needs can be bounded by it: the others are left free
        top = np.abs(v) + 2.0 * A * dt
        near = (room < top * dt + stopping_distance(top, 2.0 * A, A, J)) & np.isfinite(A)
        full = np.full(np.shape(room), np.inf)
        if not np.any(near):
            return full
        room, v, A, J = room[near], v[near], A[near], J[near]
        low, high = v - 2.0 * A * dt, v + 2.0 * A * dt
        f_hi = _overshoot(high, v, room, dt, A, J)
        f_lo = _overshoot(low, v, room, dt, A, J)
        # x <= 0 always fits; just above 0 the overshoot may jump to > 0: then 0 is the answer
        f_zero = stopping_distance(np.zeros_like(v), -v / dt, A, J) - room
        straddles = (low <= 0.0) & (high > 0.0)
        done_inf = f_hi <= 0.0  # the fastest step fits: no bound
        done_low = ~done_inf & (f_lo > 0.0)  # nothing fits: the slowest step
        done_zero = ~done_inf & ~done_low & straddles & (f_zero > 0.0)
        searching = ~(done_inf | done_low | done_zero)
        lo = np.where(straddles, 0.0, low)
        f_lo = np.where(straddles, f_zero, f_lo)
        lo = _illinois(lo, f_lo, high.copy(), f_hi, searching, (high - low) * BRAKING_TOL,
                       lambda x: _overshoot(x, v, room, dt, A, J))
        result = np.where(done_inf, np.inf, np.where(done_low, low,
                                                     np.where(done_zero, 0.0, lo)))
        full[near] = result
        return full


def _illinois(lo: np.ndarray, f_lo: np.ndarray, hi: np.ndarray, f_hi: np.ndarray,
              searching: np.ndarray, tol: np.ndarray, f) -> np.ndarray:
    """The largest x with ``f(x) <= 0`` in each bracket ``[lo, hi]`` (``f(lo) <= 0 < f(hi)``)
    where ``searching``, to ``tol``: regula falsi with the Illinois modification, a bisection
    step when the secant leaves the bracket; at most :data:`BRAKING_STEPS` steps."""
    side = np.zeros(lo.shape)  # the end the last step moved (-1 lo, 1 hi)
    for _ in range(BRAKING_STEPS):
        searching = searching & (hi - lo > tol)
        if not np.any(searching):
            break
        x = lo - f_lo * (hi - lo) / (f_hi - f_lo)
        x = np.where((x > lo) & (x < hi), x, 0.5 * (lo + hi))
        fx = f(x)
        fits = searching & (fx <= 0.0)
        breaks = searching & ~(fx <= 0.0)
        f_hi = np.where(fits & (side < 0), 0.5 * f_hi, f_hi)
        f_lo = np.where(breaks & (side > 0), 0.5 * f_lo, f_lo)
        lo, f_lo = np.where(fits, x, lo), np.where(fits, fx, f_lo)
        hi, f_hi = np.where(breaks, x, hi), np.where(breaks, fx, f_hi)
        side = np.where(fits, -1.0, np.where(breaks, 1.0, side))
    return lo
