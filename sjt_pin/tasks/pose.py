"""The full SE(3) pose of a frame (6 rows), its angular rows weighted by a length."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..kernels import frame_velocity
from ..validation import real_number
from .base import Task, jlog6_rows


def characteristic_length(robot, frame_id: int) -> float:
    """The default length L (in the URDF's length unit, m) of a pose task on ``frame_id``.

    The mean, over the moving joints of the frame's chain, of the summed link lengths from
    that joint to the frame (``sum |t_k|`` over the joint placements after it and the frame's
    placement): the lever arm of the average joint of the chain stretched out. 0.47-0.81 m on
    Bravo 7, TIAGo's arm and torso, Panda, UR5 and Baxter's arm. Why this one:

    - it scales with every length of the URDF and nothing else (in mm it is exactly 1000
      times its value in m), so a pose task with it is unit-free;
    - it does not depend on the configuration, unlike the distance from the first joint to
      the frame at ``q0`` (0.12 m on Kinova's folded reference posture, 0.85 m on UR5's
      stretched one): the task means the same wherever the solver starts;
    - it sits between the short lever arms of the wrist and the long ones of the shoulder,
      which is where SJT tracks best: on the accuracy benchmark's UR5 and Panda paths every
      SJT form's max error falls as L goes from 1 m to about 0.3-0.5 m and rises again below
      0.2 m (the wrist joints, whose columns are then mostly L J_w, move too fast for the
      linear model), and the chain's full reach (1.24 m on UR5) is 1.1-1.8x worse than this.

    Falls back to 1.0 when the chain has no length at all (a frame on a joint's axis).
    """
    model = robot.model
    frame = model.frames[frame_id]
    support = list(model.supports[frame.parentJoint][1:])
    tail = float(np.linalg.norm(frame.placement.translation))
    links = {j: float(np.linalg.norm(model.jointPlacements[j].translation)) for j in support}
    reaches = [tail + sum(links[k] for k in support if k > j)
               for j in support if model.joints[j].nv > 0]
    length = float(np.mean(reaches)) if reaches else 0.0
    return length if length > 0.0 else 1.0


def tasks_length(robot, tasks) -> float:
    """The characteristic length (m) of ``tasks``: the largest of the pose tasks' ``length``
    and of :func:`characteristic_length` on the other target-taking tasks' frames (1.0 without
    any). A solver takes its first priority level's (``TaskStack.leading``: a lower level's
    tasks leave the first level's step as it is); unit-free thresholds are fractions of it
    (SJT's floor under the column norms, the least-squares methods' error-dependent damping,
    the escape's converged error)."""
    lengths = [getattr(t, "length", None) or characteristic_length(robot, t.frame_id)
               for t in tasks if t.takes_target and t.frame_id >= 0]
    return max(lengths, default=1.0)


def checked_length(length, name: str = "length") -> float | None:
    """``length`` (m) as a positive finite float, or ``None`` (the robot's default)."""
    if length is None:
        return None
    value = real_number(length, name, "m")
    if not 0.0 < value < float("inf"):
        raise ValueError(f"{name} must be a finite length > 0 (m) or None, got {length!r}")
    return value


class PoseTask(Task):
    """Full pose: 6 rows ``[e_p (m); L e_w (m)]`` in the frame's LOCAL axes.

    ``e = log6(oMf^-1 oMd)`` (Pinocchio's ``log6``, [m; rad]) with the frame's LOCAL Jacobian,
    the CLIK law's choice (pink and mink use ``-Jlog6 J`` instead, which agrees to first
    order; :meth:`error_jacobian` gives those exact rows, the set-point search's model).
    The desired velocity ``[p_dot_d, omega_d]`` (world axes at the desired origin) becomes the
    twist of the frame in LOCAL axes. Targets are ``pin.SE3`` or 4x4 homogeneous
    matrices.

    Args:
        frame: name of the task frame; ``None`` for the robot's end effector.
        weight: a positive number or one per row (dimensionless), see :class:`Task`.
        length: the characteristic length L (m, > 0) by which the angular rows are weighted,
            so that the mappings see ``[e_p; L e_w]`` and ``[J_v; L J_w]`` (and the feed-forward
            ``[p_dot; L omega]``): every row is a length. ``None`` (default): the robot's
            :func:`characteristic_length` for this frame.

    Why a length: a pose error mixes metres and radians, so a change of the length unit
    scales only its linear rows, and every mapping that weighs rows against each other (SJT's
    ``alpha_i = 1 / (J_i^T W J_i)``, eq. 18, the damping of the damped updates) changes its
    answer. With L in the same unit, scaling every length by s scales every row by s: the
    scaling factors by 1/s^2, ``D J^T e`` not at all, ``J D J^T`` and SJT's damping
    ``mu^2 + |e_w| sqrt(max alpha_i)`` not at all, so every SJT form (and JT and JP with
    "auto") gives the same joint trajectory in mm as in m. DLS's damping lambda is then in
    that length unit for every row (0.05 means 5 cm, or 0.05 / L rad), not unit-free.
    :attr:`Solver.last`'s ``error`` stays ``[e_p (m); e_w (rad)]``, unweighted.
    """

    dim = 6
    log6_error = True

    def __init__(self, frame: str | None = None, weight=None, length: float | None = None,
                 priority: int | None = 0):
        super().__init__(frame, weight, priority)
        self.length = checked_length(length)
        self._ff = np.zeros(6)
        self._error = np.zeros(6)  # e at the last compute

    def bind(self, robot):
        bound = super().bind(robot)
        bound.length = (characteristic_length(robot, bound.frame_id) if self.length is None
                        else self.length)
        base = np.ones(6) if self.sqrt_weight is None else self.sqrt_weight
        bound.sqrt_weight = base * np.array([1.0, 1.0, 1.0, bound.length, bound.length,
                                             bound.length])
        bound._ff = np.zeros(6)
        return bound

    def write_into(self, J, e, ff):
        self._ff = ff  # the feed-forward is computed here; J and e come from Pinocchio

    def compute(self, kinematics, target, velocity):
        oMf = kinematics.placement(self.frame_id)
        self.placement = oMf
        J = kinematics.jacobian(self.frame_id)
        self._error = e = pin.log6(oMf.actInv(target)).vector
        if velocity is None:
            return J, e, None
        frame_velocity(oMf.np, target.np, velocity, self._ff)
        return J, e, self._ff

    def error_jacobian(self, J):
        """``Jlog6(oMd^-1 oMf) J``: the exact rows of ``e = log6(oMf^-1 oMd)`` (``-de/dq``;
        Pinocchio's ``Jlog6``, as in its own IK example, computed from e, compiled)."""
        return jlog6_rows(self._error, J)

    def __repr__(self) -> str:
        frame = f"frame={self.frame!r}" if self.frame else "end effector"
        length = "" if self.length is None else f", length={self.length:g}"
        return f"PoseTask({frame}{length})"
