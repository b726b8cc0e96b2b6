"""The task protocol: what one block of rows of the CLIK law contributes.

A task turns the :class:`~sjt_pin.kinematics.Kinematics` of the current configuration and a
desired target into the three pieces of the CLIK law ``q_dot = M(J) (x_dot_d + K e)`` (paper
eq. 5, 10, 21): its error ``e = x_d - x`` (dim,), its Jacobian rows ``J = dx/dq`` (dim, nv), so
that ``e_dot = x_dot_d - J q_dot``, and the desired velocity ``x_dot_d`` in its own rows. The
solver stacks the rows of all its tasks. A new task is one subclass with ``compute`` (and
``target``/``velocity`` when its targets are not poses); see docs/extending.md.
"""

from __future__ import annotations

import copy
from abc import ABC, abstractmethod
from typing import Any, ClassVar

import numpy as np
import pinocchio as pin

from ..kernels import jlog6_inverse, rotation_defect
from ..kinematics import Kinematics
from ..validation import RIGID_TOL, as_motion, as_pose, as_vector, real_number


def checked_weight(weight) -> np.ndarray:
    """``weight`` as a 0-d array (one value for every row) or a vector of positive numbers
    (dimensionless); its length is checked where the rows are known."""
    if np.ndim(weight) == 0:
        w = np.asarray(real_number(weight, "weight"))
    elif np.asarray(weight).dtype == bool:
        raise TypeError(f"weight must be numbers, got {weight!r}")
    else:
        w = as_vector(weight, "weight")
    if not np.all(np.isfinite(w)) or np.any(w <= 0):
        raise ValueError(f"weight must be positive (a number or one per row), got {weight!r}")
    return w


def checked_priority(priority) -> int | None:
    """``priority`` as an int >= 0, or ``None`` (below every other level)."""
    if priority is None:
        return None
    if isinstance(priority, bool) or not isinstance(priority, (int, np.integer)) or priority < 0:
        raise ValueError(f"priority must be an int >= 0 (0: the highest level) or None (the "
                         f"lowest), got {priority!r}")
    return int(priority)


def jlog6_rows(error: np.ndarray, J: np.ndarray) -> np.ndarray:
    """``Jlog6(N^-1) J`` for a pose error ``error = log6(N)`` (6,) and its rows ``J`` (6, nv):
    the pose tasks' :meth:`Task.error_jacobian`."""
    G = np.empty((6, 6))
    jlog6_inverse(error, G)
    return G @ J


class Task(ABC):
    """Base class: ``dim`` rows on one frame (default: the robot's end effector).

    Args:
        frame: name of the task frame; ``None`` for the robot's end effector.
        weight: a positive number or one per row (dimensionless): rows are weighted in the
            least-squares sense, the mappings see ``sqrt(W) J`` and ``sqrt(W) e``, so SJT's
            scaling factors become ``alpha_i = 1 / (J_i^T W J_i)`` (eq. 18 with a weighted
            norm). Weights order tasks within one priority level.
        priority: the task's level (an int >= 0; 0, the default, is the highest). A lower
            level moves only in the null space of the levels above it, so it costs them
            nothing where the limits allow (Siciliano and Slotine's recursion); ``None``: below
            every other level (a posture task's default).

    A task given to a solver is bound to its robot (:meth:`bind` returns a copy), so one task
    object can serve several solvers.
    """

    dim: int
    #: whether ``step`` takes a target for this task (a posture task has its own reference)
    takes_target: ClassVar[bool] = True
    #: whether the Jacobian rows never change (the stack then copies them once)
    constant_jacobian: ClassVar[bool] = False
    #: whether the task is on a frame (a centre-of-mass or posture task is not: ``frame`` is
    #: then ``None``, and the task's key is its ``label``)
    has_frame: ClassVar[bool] = True
    #: whether the error is SE(3)'s logarithm ``log6`` (6 rows, as :class:`PoseTask`'s): its
    #: exact rows are then ``Jlog6 J`` (:meth:`error_jacobian`), which the step takes on the
    #: first level (the method's and the stage's model) from a rest at a position range short
    #: of the target on (docs/limits.md)
    log6_error: ClassVar[bool] = False

    def __init__(self, frame: str | None = None, weight=None, priority: int | None = 0):
        if frame is not None and not isinstance(frame, str):
            raise TypeError(f"frame must be a frame name (str) or None, got {frame!r}")
        self.priority = checked_priority(priority)
        self.frame = frame
        #: a frameless task's key (the key it sits under in a ``{key: task}`` mapping)
        self.label: str | None = None
        self._weight = weight
        self.sqrt_weight: np.ndarray | None = None
        if weight is not None and getattr(self, "dim", None) is not None:
            self.sqrt_weight = self._sqrt_weight(weight, self.dim)
        self.frame_id = -1
        #: world pose of the task frame at the last ``compute`` (``None`` for frameless tasks)
        self.placement: pin.SE3 | None = None

    @staticmethod
    def _sqrt_weight(weight, dim: int) -> np.ndarray:
        w = checked_weight(weight)
        if w.ndim == 1 and w.shape != (dim,):
            raise ValueError(f"weight must have shape ({dim},), got shape {w.shape}")
        return np.sqrt(np.broadcast_to(w, (dim,))).copy()

    def bind(self, robot) -> Task:
        """A copy of this task for ``robot``: its frame resolved (``FrameNotFound`` if absent)."""
        bound = copy.copy(self)
        if not self.has_frame:
            bound.frame, bound.frame_id = None, -1
            return bound
        bound.frame_id = robot.ee_frame_id if self.frame is None else robot.frame_id(self.frame)
        bound.frame = robot.model.frames[bound.frame_id].name
        return bound

    @property
    def key(self) -> str | None:
        """The key of this task's target in a ``{key: target}`` mapping: its frame's name.
        Tasks on the same frame share it (and so their target, e.g. a position task and an
        orientation task with different weights); a task over several frames names its own,
        a task without a frame its ``label``."""
        return self.frame if self.has_frame else self.label

    def joints(self, model: pin.Model) -> list[int]:
        """The ids of the Pinocchio joints whose motion changes this task's rows (the columns
        the solver may move for it): by default the joints that support its frame. A task that
        reads several frames returns the joints of all of them; its Jacobian's columns of the
        other joints must be zero."""
        return list(model.supports[model.frames[self.frame_id].parentJoint][1:])

    def write_into(self, J: np.ndarray, e: np.ndarray, ff: np.ndarray) -> None:  # noqa: B027
        """Offer views of the stacked buffers for this task's rows: a task may compute its
        rows straight into them (and return them) instead of into arrays of its own."""

    def target(self, value) -> Any:
        """``value`` validated and converted for :meth:`compute` (default: a rigid pose)."""
        if type(value) is pin.SE3 and rotation_defect(value.np) <= RIGID_TOL:
            return value  # the usual case, one compiled test (a NaN translation shows in e)
        return as_pose(value, "target")

    def velocity(self, value) -> np.ndarray:
        """A desired velocity ``pin.Motion`` or 6-vector [linear (m/s), angular (rad/s)], world
        axes at the desired frame's origin, as a 6-vector."""
        return as_motion(value)

    @abstractmethod
    def compute(self, kinematics: Kinematics, target, velocity
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """``(J, e, x_dot_d)`` at the configuration of ``kinematics``: Jacobian rows (dim, nv),
        error (dim,) and desired task velocity (dim,), or ``None`` when ``velocity`` is."""

    def error_jacobian(self, J: np.ndarray) -> np.ndarray:
        """The exact rows of the error at the last :meth:`compute`: ``J_e`` with
        ``e_dot = -J_e q_dot`` for a fixed target (the rows' convention), from its rows ``J``
        (dim, nv); the set-point search's Gauss-Newton model. The CLIK law's rows are the task
        velocity: they give ``e_dot`` only to first order near the target, and a logarithmic
        error (``log6``, ``log3``) bends away from them as it grows, so that a search step along
        ``J`` alone can point uphill (a floating base far from its target). Default: ``J``,
        exact for an error linear in q (position rows; posture rows of joints that are vector
        spaces: a posture task keeps its identity rows on a free flyer too). A new task whose
        rows are only first order overrides it."""
        return J

    def __repr__(self) -> str:
        frame = f"frame={self.frame!r}" if self.frame else "end effector"
        return f"{type(self).__name__}({frame})"


#: what the compiled task kernels take for "no desired velocity"
_NO_VELOCITY = np.zeros(0)
