"""The orientation of a frame (3 rows)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..kernels import frame_velocity
from .base import Task


class OrientationTask(Task):
    """Orientation of the frame: 3 rows (rad) in the frame's LOCAL axes.

    ``e = log3(R^T R_d)`` with the angular rows of the LOCAL Jacobian; the desired angular
    velocity (world axes) becomes ``R^T omega_d``. Targets are poses (only the rotation is used).
    """

    dim = 3

    def bind(self, robot):
        bound = super().bind(robot)
        bound._ff = np.zeros(6)
        return bound

    def compute(self, kinematics, target, velocity):
        oMf = kinematics.placement(self.frame_id)
        self.placement = oMf
        J = kinematics.jacobian(self.frame_id)[3:]
        e = pin.log3(oMf.actInv(target).rotation)
        if velocity is None:
            return J, e, None
        frame_velocity(oMf.np, target.np, velocity, self._ff)
        return J, e, self._ff[3:]
