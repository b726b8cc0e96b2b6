"""The robot's centre of mass along some world axes: a task without a frame."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..model_measures import check_mass
from ..validation import as_vector, axis_rows
from .base import Task


class CoMTask(Task):
    """The whole robot's centre of mass ``c`` (m, world axes) along a subset of the world axes.

    ``e = c_d - c`` on the chosen axes, with the rows of Pinocchio's centre-of-mass Jacobian
    ``J_c = dc/dq`` (3, nv): on a legged robot the floating base's columns are what moves the
    body over its feet. Targets are 3-vectors (m; only the chosen axes are used), velocities
    3-vectors (m/s). The task has no frame: in a ``{key: task}`` mapping it sits under any key
    (its targets then use that key), and on its own its key is ``"com"``.

    Args:
        axes: any non-empty subset of ``"xyz"``, e.g. ``"xy"`` to move the centre of mass over
            the ground and leave its height free.
        weight: a positive number or one per row (dimensionless), see :class:`Task`.
        priority: the task's level (0, the default, is the highest).

    ``placement`` (after a step) is the centre of mass as a pose with the world's axes.
    """

    has_frame = False

    def __init__(self, axes: str = "xyz", weight=None, priority: int | None = 0):
        self._rows = axis_rows(axes)
        #: the rows as a slice where they are consecutive ("xy", "yz", ...): a slice's copy
        #: is cheaper than a gather's, and the values are the same
        first = int(self._rows[0])
        self._take = (slice(first, first + len(axes))
                      if self._rows.tolist() == list(range(first, first + len(axes)))
                      else self._rows)
        self.axes, self.dim = axes, len(axes)
        super().__init__(None, weight, priority)
        self.label = "com"

    def bind(self, robot):
        check_mass(robot.model, robot.name, "CoMTask")
        bound = super().bind(robot)
        d, n = self.dim, robot.nv
        bound._J, bound._e, bound._ff = np.zeros((d, n)), np.zeros(d), np.zeros(d)
        bound.placement = pin.SE3.Identity()
        return bound

    def write_into(self, J, e, ff):
        self._J, self._e, self._ff = J, e, ff  # (the rows are computed straight into them)

    def joints(self, model):
        return list(range(1, model.njoints))  # every body with mass moves the centre of mass

    def target(self, value):
        if (type(value) is np.ndarray and value.shape == (3,) and value.dtype == np.float64
                and value.flags.c_contiguous):
            return value  # finiteness shows in the error
        return as_vector(value, "target", 3)

    def velocity(self, value):
        if (type(value) is np.ndarray and value.shape == (3,) and value.dtype == np.float64
                and value.flags.c_contiguous):
            return value  # finiteness shows in the feed-forward
        return as_vector(value, "target_velocity", 3)

    def compute(self, kinematics, target, velocity):
        c, Jc = kinematics.center_of_mass()
        self.placement.translation = c
        rows = self._take
        self._J[...] = Jc[rows]
        if target is not None:
            np.subtract(target[rows], c[rows], out=self._e)
        if velocity is None:
            return self._J, self._e, None
        self._ff[...] = velocity[rows]
        return self._J, self._e, self._ff

    def __repr__(self) -> str:
        return f"CoMTask(axes={self.axes!r})"
