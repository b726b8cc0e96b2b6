"""A joint-space pull toward a reference configuration."""

from __future__ import annotations

import numpy as np

from ..validation import as_vector
from .base import Task, checked_weight


class PostureTask(Task):
    """Every joint pulled toward ``q_ref`` (nv rows; rad or m per joint), for redundant robots.

    Stacked under the other tasks with a low ``weight`` (dimensionless per joint, default
    1e-2), it keeps the self-motion of a 7-DoF arm from drifting over long runs at the price of
    a small bias of the main tasks of order ``weight``. Its error is ``q_ref ⊖ q`` (Pinocchio's
    ``difference``), its rows the identity; SJT's scaling factors then become
    ``alpha_i = 1 / (J_i^T W J_i + weight_i)``, and the loop's eigenvalues stay in [0, n].
    ``q_ref`` defaults to the robot's ``q0``. It takes no target: ``step`` leaves it out of the
    targets and its rows take the scalar gain (the mean gain when the gain is given per row).
    """

    takes_target = False
    constant_jacobian = True

    def __init__(self, q_ref=None, weight=1e-2):
        self.q_ref = None if q_ref is None else as_vector(q_ref, "q_ref")
        self.weight = checked_weight(weight)
        super().__init__(None, None)

    def bind(self, robot):
        bound = super().bind(robot)
        bound.frame, bound.frame_id = None, -1
        bound.dim = robot.nv
        bound.q_ref = robot.q0.copy() if self.q_ref is None else robot.check_q(self.q_ref,
                                                                                 "q_ref")
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
