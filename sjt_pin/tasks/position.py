"""The position of a frame's origin along some world axes."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..exceptions import FrameNotFound
from ..kernels import position_rows
from ..validation import as_pose, as_vector, axis_rows
from .base import _NO_VELOCITY, Task


class PositionTask(Task):
    """Position of the frame origin along a subset of the world axes (m).

    ``frame`` is the task frame (``None``: the robot's end effector), first as in every task;
    ``axes`` is any non-empty subset of ``"xyz"`` in any order, e.g. ``"xy"`` for a planar arm.
    ``e = p_d - p`` in world axes, with the linear rows of the LOCAL_WORLD_ALIGNED Jacobian.
    Targets are 3-vectors (m) or poses (``pin.SE3``, 4x4: only the translation is used);
    velocities are ``pin.Motion``, 6-vectors (the linear part is used) or 3-vectors (m/s).

    With position rows only, nothing bounds SJT's scaling factors from above: a joint whose
    axis passes 1 mm from the point has ``|J_i| = 1e-3`` and ``alpha_i = 1e6``. SJT's
    ``length`` l (default 0.1 m, see :class:`~sjt_pin.SJTSolver`) is the floor:
    ``alpha_i = 1 / max(|J_i|^2, l^2)``, so ``|q_dot_i| <= k |e| / l``.
    """

    def __init__(self, frame: str | None = None, axes: str = "xyz", weight=None,
                 priority: int | None = 0):
        self._rows = axis_rows(axes)
        self.axes = axes
        self.dim = len(axes)
        super().__init__(frame, weight, priority)

    def bind(self, robot):
        try:
            bound = super().bind(robot)
        except FrameNotFound as error:
            if self.frame and not set(self.frame) - set("xyz"):  # PositionTask("xy"): axes
                raise FrameNotFound(error.name, error.available, robot.name, message=(
                    f"{error}; the frame is PositionTask's first argument, as in every "
                    f"task: for the axes write PositionTask(axes={self.frame!r})")) from None
            raise
        d, n = self.dim, robot.nv
        bound._J, bound._e, bound._ff = np.zeros((d, n)), np.zeros(d), np.zeros(d)
        return bound

    def write_into(self, J, e, ff):
        self._J, self._e, self._ff = J, e, ff  # (position_rows writes the rows straight there)

    def target(self, value):
        if (type(value) is np.ndarray and value.shape == (3,) and value.dtype == np.float64
                and value.flags.c_contiguous and value.flags.aligned):
            return value  # finiteness shows in the error
        if isinstance(value, pin.SE3):
            return value.translation
        if np.shape(value) == (4, 4):
            return as_pose(value, "target").translation
        return as_vector(value, "target", 3)

    def velocity(self, value):
        if (type(value) is np.ndarray and value.shape in ((3,), (6,))
                and value.dtype == np.float64 and value.flags.c_contiguous
                and value.flags.aligned):
            return value  # finiteness shows in the feed-forward
        if isinstance(value, pin.Motion):
            return value.vector
        size = 3 if np.shape(value) == (3,) else 6
        return as_vector(value, "target_velocity", size)

    def compute(self, kinematics, target, velocity):
        oMf = kinematics.placement(self.frame_id)
        self.placement = oMf
        J6 = kinematics.world_aligned_jacobian(self.frame_id)
        position_rows(J6, oMf.np, target, _NO_VELOCITY if velocity is None else velocity,
                      self._rows, self._J, self._e, self._ff)
        return self._J, self._e, None if velocity is None else self._ff

    def __repr__(self) -> str:
        frame = f"frame={self.frame!r}, " if self.frame else ""
        return f"PositionTask({frame}axes={self.axes!r})"
