"""Joint position limits: clamp the joints that would leave their range, remap the others."""

from __future__ import annotations

import numpy as np

from ..kernels import clamp_pass
from .base import Limit


class PositionLimit(Limit):
    """The URDF position limits of 1-DoF joints (revolute, prismatic) are never crossed.

    A solver runs this limit inside its step kernel (the box and the clamping pass of
    :mod:`sjt_pin.kernels.methods`); these methods are the reference it is tested against and
    what a further solver's ``limits=`` would use.

    A joint whose update would leave its range is clamped out of the update: it moves exactly
    onto its limit (or stays there) and its column is removed from the mapping, which is
    recomputed for the task velocity that joint no longer provides, so the other joints take
    over. A joint that starts outside its range (a start configuration out of range) is driven
    back toward it at its speed limit (``recovery_speeds``, rad/s or m/s), never jumped.

    Args:
        robot: where the limits come from (``robot.lower_limits``, ``upper_limits``).
        moving: (nv,) 1 for the joints the solver moves; the others are not tested.
        recovery_speeds: (nv,) speed at which a joint outside its range returns (rad/s, m/s).
    """

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
        self.recovery_speeds = np.asarray(recovery_speeds, dtype=float)[self.v_index]
        self._fixed = np.zeros(model.nv)
        self._fixed_step = np.zeros(model.nv)

    @property
    def active(self) -> bool:
        """Whether any moving joint has position limits."""
        return self.q_index.size > 0

    def violated(self, q, step, dt):
        new = q[self.q_index] + step[self.v_index]
        return bool(np.any(new > self.upper) or np.any(new < self.lower))

    def enforce(self, q, step, dt, remap):
        fixed, fixed_step = self._fixed, self._fixed_step
        fixed[:] = 0.0
        fixed_step[:] = 0.0
        for _ in range(self.q_index.size):
            if not clamp_pass(q, step, self.q_index, self.v_index, self.lower, self.upper,
                              self.recovery_speeds, dt, fixed, fixed_step):
                break
            # the free joints take over the task velocity the fixed ones no longer provide
            held = fixed != 0.0
            step = remap(~held, fixed_step / dt)
            step[held] = fixed_step[held]
        return step
