"""Joint position limits, approached with a speed that can still stop in time."""

from __future__ import annotations

import numpy as np

from .base import Limit

#: the share of the acceleration and jerk limits that a braking plan keeps in reserve (the
#: compiled stage's ``BoundsConfig::kReserve``): the other joints' coupling through the task may
#: take it from a step
BRAKING_RESERVE = 0.2


class PositionLimit(Limit):
    """The URDF position limits of 1-DoF joints (revolute, prismatic) are never crossed.

    The compiled stage bounds each limited joint's velocity so that the step ends inside the
    range, ``q_dot <= (upper - q) / dt``, and — when the solver has acceleration (and jerk)
    limits — so that the joint can still stop before the limit: ``q_dot dt + s(q_dot) <=
    upper - q`` with the exact distance ``s`` of a braking at the acceleration limit reached
    and left at the jerk limit from this step's velocity and acceleration, planned with
    :data:`BRAKING_RESERVE` of the limits in reserve (``sjt_pin/kernels/src/braking.hpp``). A
    joint approaching its limit thus brakes in time and never stops in one step. A joint that
    starts outside its range returns at ``recovery_speeds`` (rad/s or m/s), ramped within the
    acceleration and jerk limits, never a jump.

    This object is the table of limited joints the stage reads: ``q_index``, ``v_index`` (their
    index in q and in the velocity), ``lower``, ``upper`` (rad or m) and ``recovery_speeds``.

    Args:
        robot: where the limits come from (``robot.lower_limits``, ``upper_limits``).
        moving: (nv,) 1 for the joints the solver moves; the others are not bounded.
        recovery_speeds: (nv,) speed at which a joint outside its range returns (rad/s, m/s).
    """

    name = "position"

    def __init__(self, robot, moving: np.ndarray, recovery_speeds: np.ndarray):
        model = robot.model
        lower, upper = robot.lower_limits, robot.upper_limits
        qi, vi = [], []
        for j in range(1, model.njoints):
            joint = model.joints[j]
            if (joint.nq == 1 and joint.nv == 1 and moving[joint.idx_v]
                    and np.isfinite(lower[joint.idx_q]) and np.isfinite(upper[joint.idx_q])):
                qi.append(joint.idx_q)
                vi.append(joint.idx_v)
        self.q_index = np.array(qi, dtype=np.int64)
        self.v_index = np.array(vi, dtype=np.int64)
        self.lower = lower[self.q_index].copy()
        self.upper = upper[self.q_index].copy()
        self.recovery_speeds = np.asarray(recovery_speeds, dtype=float)[self.v_index].copy()

    @property
    def active(self) -> bool:
        """Whether any moving joint has position limits."""
        return self.q_index.size > 0

    def __repr__(self) -> str:
        return f"PositionLimit({self.q_index.size} joints)"
