"""Joint position limits, approached with a speed that can still stop in time."""

from __future__ import annotations

import numpy as np

from .base import Limit, Motion

#: the share of the acceleration and jerk limits that a braking plan keeps in reserve
BRAKING_RESERVE = 0.2


class PositionLimit(Limit):
    """The URDF position limits of 1-DoF joints (revolute, prismatic) are never crossed.

    Bounds each limited joint's velocity so that the step ends inside the range,
    ``q_dot <= (upper - q) / dt``, and — when the solver has acceleration (and jerk) limits —
    so that the joint can still stop before the limit: ``q_dot dt + s(q_dot) <= upper - q``
    with the stopping distance ``s(v) = v^2 / (2 a) + v a / (2 j)`` of a braking at the
    acceleration limit ``a`` reached at the jerk limit ``j`` (an upper bound of the exact
    jerk-limited distance; with the joint still accelerating toward the limit, the distance
    that ramping that acceleration down adds is counted too). A joint approaching its limit
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
    ramp the deceleration to ``A`` (or to the peak of a triangular profile when ``A`` is not
    reached); hold it; ramp back to 0. When the deceleration ``-a0`` is already more than the
    velocity needs, ``w`` times the time to ramp it down bounds the distance."""
    finite = np.isfinite(J)
    inv_j = np.where(finite, 1.0 / np.where(finite, J, 1.0), 0.0)
    jerk = np.where(finite, J, 0.0)
    up = np.maximum(a0, 0.0)  # speeding up: ramp a0 down to 0 first
    t0 = up * inv_j
    d0 = w * t0 + up * t0 * t0 / 3.0
    w = w + 0.5 * up * up * inv_j
    beta = np.maximum(-a0, 0.0)  # already braking at beta
    # trapezoid: ramp beta -> A, hold A, ramp A -> 0
    t1 = (A - beta) * inv_j
    d1 = w * t1 - 0.5 * beta * t1 * t1 - jerk * t1 ** 3 / 6.0
    v1 = w - 0.5 * (A * A - beta * beta) * inv_j
    v2 = 0.5 * A * A * inv_j
    t2 = np.maximum(v1 - v2, 0.0) / A
    trapezoid = d1 + v1 * t2 - 0.5 * A * t2 * t2 + A ** 3 * inv_j * inv_j / 6.0
    # triangle: peak a_p with (a_p^2 - beta^2) / 2J + a_p^2 / 2J = w, then back to 0
    a_p = np.sqrt(np.maximum(w * jerk + 0.5 * beta * beta, 0.0))
    ta = (a_p - beta) * inv_j
    triangle = np.where(a_p >= beta,
                        w * ta - 0.5 * beta * ta * ta - jerk * ta ** 3 / 6.0
                        + a_p ** 3 * inv_j * inv_j / 6.0,
                        w * beta * inv_j)
    return d0 + np.where(v1 >= v2, trapezoid, triangle)


def braking_speed(room: np.ndarray, v: np.ndarray, a: np.ndarray, dt: float,
                  acceleration: np.ndarray | None, jerk: np.ndarray | None) -> np.ndarray:
    """The largest velocity x toward a point ``room`` away (rad or m: a position limit, or the
    rest of the way to a target) after which a joint can still stop before it within the
    ``acceleration`` and ``jerk`` limits (``inf`` without an acceleration limit); ``v`` is its
    previous velocity toward that point (rad/s), so this step's acceleration is
    ``(x - v) / dt`` (``a``, the previous acceleration, is not needed).

    The condition ``x dt + stopping_distance(x, (x - v) / dt) <= room`` grows with x; it is
    solved by bisection (40 halvings) between ``v - A dt`` and ``v + A dt`` (what one step can
    reach), and without a jerk limit in closed form, ``x dt + x^2 / (2 A) <= room``.
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
        # needs can be bounded by it: the others are left free (bisection is the cost here)
        top = np.abs(v) + 2.0 * A * dt
        near = room < top * dt + stopping_distance(top, 2.0 * A, A, J)
        if not np.any(near):
            return np.full(np.shape(room), np.inf)
        full = np.full(np.shape(room), np.inf)
        room, v, A, J = room[near], v[near], A[near], J[near]

        def fits(x):
            positive = np.maximum(x, 0.0)
            return x * dt + np.where(x > 0, stopping_distance(
                positive, (x - v) / dt, A, J), 0.0) <= room

        low, high = v - 2.0 * A * dt, v + 2.0 * A * dt
        ok_high = fits(high)
        for _ in range(40):
            middle = 0.5 * (low + high)
            good = fits(middle)
            low = np.where(good, middle, low)
            high = np.where(good, high, middle)
        full[near] = np.where(ok_high | ~np.isfinite(A), np.inf, low)
        return full
