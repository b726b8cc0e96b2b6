"""Joint position limits, approached with a speed that can still stop in time."""

from __future__ import annotations

import numpy as np

from .base import Limit, Motion


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
    jumps.

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
        upper = np.minimum(braking_speed(room_up, v, a, dt, self.acceleration, self.jerk),
                           room_up / dt)
        lower = -np.minimum(braking_speed(room_down, -v, -a, dt, self.acceleration, self.jerk),
                            room_down / dt)
        # outside the range: back toward it at the recovery speed, no further than the limit
        above, below = room_up < 0, room_down < 0
        back = np.minimum(self.recovery_speeds, np.abs(np.where(above, room_up, room_down)) / dt)
        lower = np.where(above, -back, np.where(below, back, lower))
        upper = np.where(above, -back, np.where(below, back, upper))
        lo, hi = np.full(self.nv, -np.inf), np.full(self.nv, np.inf)
        lo[self.v_index], hi[self.v_index] = lower, upper
        return lo, hi


def braking_speed(room: np.ndarray, v: np.ndarray, a: np.ndarray, dt: float,
                  acceleration: np.ndarray | None, jerk: np.ndarray | None) -> np.ndarray:
    """The largest velocity toward a point ``room`` away (rad or m; a position limit, or the
    rest of the way to a target) after which a joint can still stop before it within the
    ``acceleration`` and ``jerk`` limits (``inf`` without an acceleration limit); ``v`` and
    ``a`` are its previous velocity and acceleration toward that point (rad/s, rad/s^2).

    The stopping distance is bounded by ``s(w) = w^2 / (2 A) + w A / (2 J)`` (braking at the
    acceleration limit A, reached and left at the jerk limit J; it bounds the exact
    jerk-limited distance of both the trapezoidal and the triangular profile), after ramping
    down an acceleration toward the point that this step may still have (``a + J dt``,
    capped at A), which adds ``c0 = a_b^2 / (2 J)`` to the velocity and ``a_b^3 / (3 J^2)`` plus
    ``v a_b / J`` to the distance; with this step's own ``v dt`` the condition is a quadratic
    in v.
    """
    if acceleration is None:
        return np.full(np.shape(room), np.inf)
    A = acceleration
    J = np.full(np.shape(room), np.inf) if jerk is None else jerk
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        finite_j = np.isfinite(J)
        inv_j = np.where(finite_j, 1.0 / J, 0.0)
        a_b = np.where(finite_j, np.clip(a + np.where(finite_j, J, 0.0) * dt, 0.0, A), 0.0)
        c0 = 0.5 * a_b * a_b * inv_j
        b = dt + a_b * inv_j + c0 / A + 0.5 * A * inv_j
        c = a_b ** 3 * inv_j * inv_j / 3.0 + 0.5 * c0 * c0 / A + 0.5 * c0 * A * inv_j - room
        disc = b * b - 2.0 * c / A
        speed = A * (-b + np.sqrt(np.maximum(disc, 0.0)))
        # too late to stop in time (a start the solver did not command): brake at the limit
        speed = np.where(disc >= 0, speed, v - A * dt)
        return np.where(np.isfinite(A), speed, np.inf)
