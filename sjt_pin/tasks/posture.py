"""A joint-space pull toward a reference configuration."""

from __future__ import annotations

import numpy as np

from ..validation import as_vector
from .base import Task, checked_weight


class PostureTask(Task):
    """Every joint pulled toward ``q_ref`` (nv rows; rad or m per joint), for redundant robots.

    By default (``priority=None``) it is the lowest priority level: it moves the joints only in
    the null space of the tasks above it, so their tracking is the same with or without it,
    and it keeps the self-motion of a 7-DoF arm from drifting over long runs. There its joint
    velocity is ``weight K (q_ref ⊖ q)`` (K: the solver's gain, ``1/dt`` for "auto"), so
    ``weight`` (dimensionless per joint, default 1e-2) sets how fast it pulls: a time constant
    of ``dt / weight``, 0.1 s at 1 kHz. Given ``priority=0`` it is stacked with the tasks
    instead, a weighted compromise that biases them by about ``weight``. Its error is
    ``q_ref ⊖ q`` (Pinocchio's ``difference``), its rows the identity; ``q_ref`` defaults to
    the robot's ``q0``. It takes no target: ``step`` leaves it out of the targets, and its rows
    take the scalar gain (the mean gain when the gain is given per row).
    """

    takes_target = False
    constant_jacobian = True
    has_frame = False

    def __init__(self, q_ref=None, weight=1e-2, priority: int | None = None):
        self.q_ref = None if q_ref is None else as_vector(q_ref, "q_ref")
        self.weight = checked_weight(weight)
        super().__init__(None, None, priority)

    def bind(self, robot):
        bound = super().bind(robot)
        bound.dim = robot.nv
        bound.q_ref = (robot.q0 if self.q_ref is None  # (its own copy, never the caller's)
                       else robot.check_q(self.q_ref, "q_ref")).copy()
        bound.sqrt_weight = self._sqrt_weight(self.weight, robot.nv)
        bound._J = np.eye(robot.nv)
        return bound

    def joints(self, model):
        return list(range(1, model.njoints))  # a posture task moves every joint

    def compute(self, kinematics, target, velocity):
        if kinematics.q is None:  # asked for its constant rows before any configuration
            return self._J, np.zeros(self.dim), None
        return self._J, kinematics.difference(self.q_ref), None

    def __repr__(self) -> str:
        return f"PostureTask(weight={self.weight})"
