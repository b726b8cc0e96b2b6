"""The orientation of a frame (3 rows), weighted by a length."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..kernels import frame_velocity
from ..validation import as_pose
from .base import Task
from .pose import characteristic_length, checked_length


class OrientationTask(Task):
    """Orientation of the frame: 3 rows ``L e_w`` in the frame's LOCAL axes.

    ``e = log3(R^T R_d)`` (rad) with the angular rows of the LOCAL Jacobian; the desired
    angular velocity (world axes) becomes ``R^T omega_d``. Targets are poses (only the
    rotation is used) or 3x3 rotation matrices.

    Args:
        frame: name of the task frame; ``None`` for the robot's end effector.
        weight: a positive number or one per row (dimensionless), see :class:`Task`.
        length: the characteristic length L (m, > 0) the rows are weighted by, as the angular
            rows of a :class:`PoseTask`; ``None`` (default): the robot's
            :func:`~sjt_pin.tasks.pose.characteristic_length` for this frame. Alone, an
            orientation task is unit-free either way (SJT, JT and JP do not see a common
            factor of every row); stacked with position or pose rows of other frames, L makes
            every row a length, so that the stack is unit-free too.
    """

    dim = 3

    def __init__(self, frame: str | None = None, weight=None, length: float | None = None,
                 priority: int | None = 0):
        super().__init__(frame, weight, priority)
        self.length = checked_length(length)
        self._offset = np.eye(3)  # R^T R_d at the last compute

    def bind(self, robot):
        bound = super().bind(robot)
        bound.length = (characteristic_length(robot, bound.frame_id) if self.length is None
                        else self.length)
        base = np.ones(3) if self.sqrt_weight is None else self.sqrt_weight
        bound.sqrt_weight = base * bound.length
        bound._ff = np.zeros(6)
        return bound

    def target(self, value):
        if not isinstance(value, pin.SE3) and np.shape(value) == (3, 3):
            try:
                rotation = np.asarray(value, dtype=float)
            except (TypeError, ValueError) as exc:
                raise ValueError(f"target must be a pin.SE3, a 4x4 matrix or a 3x3 rotation, "
                                 f"got {value!r}") from exc
            homogeneous = np.eye(4)
            homogeneous[:3, :3] = rotation
            return as_pose(homogeneous, "target")  # (rigid, finite: checked there)
        return super().target(value)

    def compute(self, kinematics, target, velocity):
        oMf = kinematics.placement(self.frame_id)
        self.placement = oMf
        J = kinematics.jacobian(self.frame_id)[3:]
        self._offset = offset = oMf.actInv(target).rotation
        e = pin.log3(offset)
        if velocity is None:
            return J, e, None
        frame_velocity(oMf.np, target.np, velocity, self._ff)
        return J, e, self._ff[3:]

    def error_jacobian(self, J):
        """``Jlog3(R_d^T R) J``: the exact rows of ``e = log3(R^T R_d)`` (``-de/dq``)."""
        return pin.Jlog3(self._offset.T) @ J

    def __repr__(self) -> str:
        frame = f"frame={self.frame!r}" if self.frame else "end effector"
        length = "" if self.length is None else f", length={self.length:g}"
        return f"OrientationTask({frame}{length})"
