"""What one ``step()`` computed: :class:`StepInfo`, built from the step's buffers when
:attr:`Solver.last <sjt_pin.solver.Solver.last>` is read."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin


@dataclass(frozen=True)
class StepInfo:
    """What one ``step()`` computed, at the configuration it was given.

    Attributes:
        error: task error e (the stacked rows of the tasks that take targets, without posture
            rows; m and rad), before weights and gain.
        error_norm: Euclidean norm of ``error``.
        dq: joint velocity q_dot (nv,) in rad/s or m/s, after the escape and the limits (the
            step integrated is ``dq * dt``).
        gain: K used in this step (1/s): a number, or one per task row for a per-row gain.
        loop_bound: the bound of lambda_max(J M) that "auto" divided by (1 when the method's
            loop eigenvalues are at most 1, or with a fixed gain).
        pose: world pose of the task frame (``pin.SE3``); with several frames a dict
            ``{frame: pose}``.
        alpha: SJT's scaling factors alpha_i (nv,), 0 for joints that do not move the tasks;
            ``None`` for the other methods.
        escaped: a saddle escape velocity was added (JT, SJT).
        clamped: velocity (tangent) indices — columns of J, entries of ``dq`` — of the joints
            at a bound of the constraint stage (held there while the others take over the
            task); ``clamped_joints`` are their names.
        task_scale: the factor s in [0, 1] by which the constraint stage scaled the task
            velocity (x_dot_d + K e) because no joint velocity within the limits could meet
            all of it (1: the whole task).
        active_limits: ``(limit, joint)`` name pairs of the bounds the joint velocity is on
            (``("velocity", "torso_lift_joint")``, ``("position", "elbow_joint")``, ...).
        active_rows: names of the limits whose general rows (``A q_dot <= b``) are active.
        limit_conflicts: joints whose acceleration or jerk limit had to yield to a position or
            speed limit (a start outside the range, limits changed between steps).
        outside_limits: joints whose position in the ``q`` given to this step lay outside
            their URDF range (a seed out of range): the step moves each back toward its range
            at its recovery speed, ramped within the acceleration and jerk limits — never a
            jump — if a task moves it (a joint off every task's chain stays put unless a
            posture task is stacked); ``()`` when ``q`` was within every limit.
        velocity_scale: the same as ``task_scale`` (its former name).
    """

    error: np.ndarray
    error_norm: float
    dq: np.ndarray
    gain: float | np.ndarray
    loop_bound: float
    pose: pin.SE3 | dict
    alpha: np.ndarray | None
    escaped: bool
    clamped: np.ndarray
    clamped_joints: tuple[str, ...]
    task_scale: float = 1.0
    active_limits: tuple[tuple[str, str], ...] = ()
    active_rows: tuple[str, ...] = ()
    limit_conflicts: tuple[str, ...] = ()
    outside_limits: tuple[str, ...] = ()

    @property
    def velocity_scale(self) -> float:
        return self.task_scale

    def __repr__(self) -> str:
        return (f"StepInfo(error_norm={self.error_norm:.3g}, "
                f"|dq|={float(np.linalg.norm(self.dq)):.3g} rad/s)")
