"""What one ``step()`` computed: :class:`StepInfo`, built from the step's buffers when
:attr:`Solver.last <sjt_pin.solver.Solver.last>` is read."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

#: 1/s: a step whose motion lowers 1/2 |e_w|^2 by less than this fraction of itself per second
#: makes no progress (see :attr:`StepInfo.stalled`); unit-free, the same in mm and in m. Measured
#: on UR5 and UR10 at rest short of their targets: 3e-29 to 4e-26 1/s (zero when limits hold
#: the arm); JT on its way to a target out of reach: 5e-5 1/s and more.
STALL_RATE = 1e-6


def makes_no_progress(Jw: np.ndarray, ew: np.ndarray, dq: np.ndarray, ffw: np.ndarray,
                      floor_sq: float) -> bool:
    """Whether the joint velocity ``dq`` (nv,; rad/s, m/s) leaves the weighted error ``ew``
    (m,) where it is: ``|ew|^2 > floor_sq`` and the rate ``ew . (Jw dq - ffw)`` at which the
    motion beyond the target's own weighted velocity ``ffw`` (m,; zeros without feed-forward)
    changes ``1/2 |ew|^2`` is within ``STALL_RATE |ew|^2`` of zero either way (``Jw``: the
    weighted task rows, m x nv): an arm braking against its error (acceleration limits after a
    target jumped) is on its way, not stalled."""
    ew_sq = float(ew @ ew)
    if not ew_sq > floor_sq:
        return False
    return abs(float(ew @ (Jw @ dq - ffw))) < STALL_RATE * ew_sq


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
        stalled: the step's motion no longer reduces the task error although the error is above
            the convergence floor (``ERROR_FLOOR`` times the tasks' length, see
            :class:`~sjt_pin.escape.SaddleEscape`): the joint velocity, beyond following the
            target's own velocity, lowers ``1/2 |e_w|^2`` by less than :data:`STALL_RATE` of
            itself per second. The arm comes to rest short of the target, and the other fields
            say why: ``task_scale == 0`` with ``active_limits`` — limits hold it (the stage
            could not move the task along its own direction); otherwise a minimum of the error
            — a target out of reach, or one reachable only on another branch of the inverse
            kinematics (``solver.solve(target, q)`` searches for it; a controller does not
            jump branches), or, for JT and SJT, a saddle that the escape tests after a window
            of stalled steps (``escaped`` is then true on the steps that follow).
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
    stalled: bool = False

    @property
    def velocity_scale(self) -> float:
        return self.task_scale

    def __repr__(self) -> str:
        return (f"StepInfo(error_norm={self.error_norm:.3g}, "
                f"|dq|={float(np.linalg.norm(self.dq)):.3g} rad/s)")
