"""The full SE(3) pose of a frame (6 rows)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..kernels import frame_velocity
from .base import Task


class PoseTask(Task):
    """Full pose: 6 rows [linear (m); angular (rad)] in the frame's LOCAL axes.

    ``e = log6(oMf^-1 oMd)`` (Pinocchio's ``log6``) with the frame's LOCAL Jacobian, the CLIK
    law's choice (pink and mink use ``-Jlog6 J`` instead, which agrees to first order). The
    desired velocity ``[p_dot_d, omega_d]`` (world axes at the desired origin) becomes the twist
    of the frame in LOCAL axes. Targets are ``pin.SE3`` or 4x4 homogeneous matrices.
    """

    dim = 6

    def __init__(self, frame: str | None = None, weight=None):
        super().__init__(frame, weight)
        self._ff = np.zeros(6)

    def bind(self, robot):
        bound = super().bind(robot)
        bound._ff = np.zeros(6)
        return bound

    def write_into(self, J, e, ff):
        self._ff = ff  # the feed-forward is computed here; J and e come from Pinocchio

    def compute(self, kinematics, target, velocity):
        oMf = kinematics.placement(self.frame_id)
        self.placement = oMf
        J = kinematics.jacobian(self.frame_id)
        e = pin.log6(oMf.actInv(target)).vector
        if velocity is None:
            return J, e, None
        frame_velocity(oMf.np, target.np, velocity, self._ff)
        return J, e, self._ff
