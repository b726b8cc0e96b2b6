"""The orientation of a frame (3 rows)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..kernels import pose_feedforward
from ..validation import RIGID_TOL, check_rigid
from .base import _NO_VELOCITY, Task


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

    def target(self, value):
        if type(value) is pin.SE3:
            return value
        return super().target(value)

    def compute(self, kinematics, target, velocity):
        oMf = kinematics.placement(self.frame_id)
        self.placement = oMf
        J = kinematics.jacobian(self.frame_id)[3:]
        e = pin.log3(oMf.actInv(target).rotation)
        if not pose_feedforward(oMf.np, target.np, _NO_VELOCITY if velocity is None else velocity,
                                self._ff) <= RIGID_TOL:
            check_rigid(target)
        return J, e, None if velocity is None else self._ff[3:]
