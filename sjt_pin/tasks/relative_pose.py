"""The pose of one frame seen from another (6 rows): a task over two frames."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..kernels import frame_velocity
from .base import Task, jlog6_rows


class RelativePoseTask(Task):
    """Pose of ``frame`` in the axes of ``reference``: 6 rows [linear (m); angular (rad)] in
    ``frame``'s LOCAL axes, e.g. one hand held against the other, or a tool against a part
    carried by a second arm.

    With ``aMb = oMa^-1 oMb`` the pose of ``frame`` (b) seen from ``reference`` (a), the error
    is ``e = log6(aMb^-1 aMd)`` (the :class:`PoseTask` error with the reference frame in place
    of the world) and the rows are ``J = J_b - bXa J_a``: the LOCAL twist of b relative to a,
    ``bXa`` the adjoint of ``bMa``. Both frames' joints move: the joints that support both
    cancel exactly and are left out (:meth:`joints`). Targets are ``pin.SE3`` or 4x4
    matrices (the desired ``aMb``); a desired velocity is the twist of b relative to a,
    [linear (m/s), angular (rad/s)] in a's axes at the desired origin of b.

    Args:
        frame: the frame to place (b).
        reference: the frame it is placed in (a).
        weight: as for every task.
        name: the key of its target in a ``{key: target}`` mapping (default
            ``"<frame> in <reference>"``).
    """

    dim = 6
    log6_error = True

    def __init__(self, frame: str, reference: str, weight=None, name: str | None = None,
                 priority: int | None = 0):
        if not isinstance(frame, str) or not isinstance(reference, str):
            raise TypeError(f"frame and reference must be frame names, got {frame!r}, "
                            f"{reference!r}")
        if frame == reference:
            raise ValueError(f"frame and reference must differ, got {frame!r} twice")
        if name is not None and not isinstance(name, str):
            raise TypeError(f"name must be a str or None, got {name!r}")
        super().__init__(frame, weight, priority)
        self.reference = reference
        self.name = f"{frame} in {reference}" if name is None else name
        self.reference_id = -1
        self._J = np.zeros((6, 0))
        self._ff = np.zeros(6)
        self._error = np.zeros(6)  # e at the last compute

    @property
    def key(self) -> str:
        return self.name

    def bind(self, robot):
        bound = super().bind(robot)
        bound.reference_id = robot.frame_id(self.reference)
        bound._J = np.zeros((6, robot.nv))
        bound._ff = np.zeros(6)
        return bound

    def joints(self, model):
        def chain(frame_id):
            return set(model.supports[model.frames[frame_id].parentJoint][1:])

        return sorted(chain(self.frame_id) ^ chain(self.reference_id))

    def compute(self, kinematics, target, velocity):
        oMa = kinematics.placement(self.reference_id)
        oMb = kinematics.placement(self.frame_id)
        self.placement = oMb
        aMb = oMa.actInv(oMb)
        self._error = e = pin.log6(aMb.actInv(target)).vector
        # the twist of b relative to a, in b's axes: J_b - Ad(bMa) J_a
        np.subtract(kinematics.jacobian(self.frame_id),
                    aMb.inverse().action @ kinematics.jacobian(self.reference_id), out=self._J)
        if velocity is None:
            return self._J, e, None
        frame_velocity(aMb.np, target.np, velocity, self._ff)
        return self._J, e, self._ff

    def error_jacobian(self, J):
        """``Jlog6(aMd^-1 aMb) J``: the exact rows of ``e = log6(aMb^-1 aMd)`` (``-de/dq``)."""
        return jlog6_rows(self._error, J)

    def __repr__(self) -> str:
        return f"RelativePoseTask({self.frame!r}, reference={self.reference!r})"
