"""A contact: a frame held where it is (a foot on the ground, a hand on a handle)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..validation import as_pose
from .base import Task
from .pose import PoseTask
from .position import PositionTask

_LOCAL, _WORLD = pin.LOCAL, pin.LOCAL_WORLD_ALIGNED


class ContactTask(Task):
    """A frame held fixed: the rows of a :class:`PoseTask` (a sole, a grasp: 6 rows) or, with
    ``point=True``, of a :class:`PositionTask` (a point foot, free to roll: 3 rows) whose
    target never moves.

    The held pose is ``pose`` when given, else the frame's pose at the first step after the
    solver is built (or after :meth:`release`). It takes no target in ``step``. Put contacts on
    the top level (``priority=0``, the default) and the tasks they carry below them
    (``priority=1``, ...): those then move only in the contacts' null space, and a step's
    second-order drift is taken back by the next step's feedback. Under acceleration limits
    (without jerk limits) it is also asked back in the same step from the last step's
    velocity (:meth:`drift`), which those limits make nearly this step's: a foot then slips by
    the drift's change between steps and the third-order terms. (Under jerk limits that loop
    held Solo-12 in a 0.15 rad/s limit cycle; without acceleration limits the velocity jumps
    and the last one does not predict the drift.)
    Mind the count: a quadruped's four feet held as poses are 24 rows on 18 joints and leave
    its body no motion; as points they are 12.

    Args:
        frame: the contact frame (a sole, a foot's tip, a gripper).
        pose: the pose to hold (``pin.SE3`` or 4x4, world axes; default: where the frame is at
            the first step); with ``point=True`` only its translation counts.
        point: hold only the frame's origin (3 rows), not its orientation.
        weight, priority: as for every task; ``length``: as for :class:`PoseTask`.

    ``held`` is the pose being held (``None`` before the first step); the solver's bound
    copies are in ``solver.stack.tasks``.
    """

    takes_target = False

    def __init__(self, frame: str, pose=None, point: bool = False, weight=None,
                 length: float | None = None, priority: int | None = 0):
        if not isinstance(frame, str):
            raise TypeError(f"a contact needs its frame's name (str), got {frame!r}")
        self.point = bool(point)
        self._rows: Task = (PositionTask(frame, weight=weight, priority=priority) if self.point
                            else PoseTask(frame, weight, length, priority))
        self.dim = self._rows.dim
        super().__init__(frame, None, priority)
        self.held: pin.SE3 | None = None if pose is None else as_pose(pose, "pose")
        self._given = self.held

    def bind(self, robot):
        bound = super().bind(robot)
        bound._rows = self._rows.bind(robot)
        bound.sqrt_weight = bound._rows.sqrt_weight
        return bound

    def release(self) -> None:
        """Forget the held pose: the next step holds the frame where it then is (a foot
        lifted and set down elsewhere); a contact given ``pose=`` goes back to that pose."""
        self.held = self._given

    def write_into(self, J, e, ff):
        self._rows.write_into(J, e, ff)

    def compute(self, kinematics, target, velocity):
        if self.held is None:
            self.held = kinematics.placement(self.frame_id)
        held = self.held.translation if self.point else self.held
        out = self._rows.compute(kinematics, held, None)
        self.placement = self._rows.placement
        return out

    def drift(self, kinematics, dt: float) -> np.ndarray:
        """The rows' velocity (m/s, and rad/s for a pose) that takes back a step's second-order
        drift: over a step of ``q_dot`` a held frame moves by ``J q_dot dt + J_dot q_dot dt^2
        / 2``, so the rows ask ``J q_dot = -dt/2 J_dot q_dot``, from the velocity-product
        acceleration after :meth:`Kinematics.velocity_products
        <sjt_pin.kinematics.Kinematics.velocity_products>` (a point's classical acceleration
        in world axes; a pose's spatial acceleration in its own axes, as its rows)."""
        model, data = kinematics.model, kinematics.data
        if self.point:
            a = pin.getFrameClassicalAcceleration(model, data, self.frame_id, _WORLD).linear
        else:
            a = pin.getFrameAcceleration(model, data, self.frame_id, _LOCAL).vector
        return -0.5 * dt * a

    def error_jacobian(self, J):
        return self._rows.error_jacobian(J)

    def __repr__(self) -> str:
        point = ", point=True" if self.point else ""
        return f"ContactTask({self.frame!r}{point})"
