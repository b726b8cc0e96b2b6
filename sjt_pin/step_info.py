"""What one ``step()`` computed: :class:`StepInfo`, built from the step's buffers when
:attr:`Solver.last <sjt_pin.solver.Solver.last>` is read."""

from __future__ import annotations

import math
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
class LevelInfo:
    """One priority level of a step: ``error_norm`` (|e| of its tasks' rows but a posture's,
    task units: a contact's slip counts; 0 for a posture level) and ``scale``, the share in
    [0, 1] of the motion its rows asked for that the step kept (the projection of the achieved
    task velocity onto the asked one, over the asked one's squared norm; 1 when the limits
    left the level whole). A posture level's scale also counts the share of its self-motion
    that the first level's rank leaves it: it fades to 0 where the first level's task rows
    lose rank (an arm stretched toward a target out of reach), so that it does not swing the
    arm about a singular rest."""

    priority: int
    error_norm: float
    scale: float


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
        task_scale: the share s in [0, 1] of the method's task motion (the first level's)
            that the step kept: the achieved task velocity projected onto the asked one, over
            its squared norm (1: the method's step was within every limit, or the others took
            over what the held joints could not do).
        active_limits: ``(limit, joint)`` name pairs of the bounds the stage held a joint on
            (``("velocity", "torso_lift_joint")``, ``("position", "elbow_joint")``;
            ``"braking"``: the braking that lets a joint stop where the feedback sends it,
            under acceleration and jerk limits).
        active_rows: names of the limits whose general rows (``A q_dot <= b``) are active.
        limit_conflicts: joints whose acceleration or jerk limit had to yield to a position or
            speed limit (a start outside the range, limits changed between steps).
        rows_exceeded: ``(limit, excess)`` for each limit whose general rows the step could
            not keep within the joints' position and speed limits, ``excess`` the largest
            ``A_i q_dot - b_i`` of its rows (m/s for a :class:`~sjt_pin.CollisionLimit`:
            times ``dt``, how much more a pair closed in this step than its damper allows -
            an obstacle coming faster than the arm can give way); ``()`` when every row held.
        outside_limits: joints whose position in the ``q`` given to this step lay outside
            their URDF range (a seed out of range): the step moves each back toward its range
            at its recovery speed, ramped within the acceleration and jerk limits — never a
            jump — if a task moves it (a joint off every task's chain stays put unless a
            posture task is stacked); ``()`` when ``q`` was within every limit.
        stalled: the step's motion no longer reduces the task error although the error is above
            the convergence floor (``ERROR_FLOOR`` times the tasks' length, see
            :class:`~sjt_pin.escape.SaddleEscape`): the joint velocity, beyond following the
            target's own velocity, lowers ``1/2 |e_w|^2`` by less than :data:`STALL_RATE` of
            itself per second. The stage never stops an arm that some admissible velocity
            would bring closer in the error's linear model (the task's rows J; its step is a
            descent direction of that model whenever one exists; a projected step that
            lowers ``1/2 |e_w|^2`` by less than 1e-3 of ``|e_w|^2`` per second gives way to
            rest, unless the escape adds it), so the arm is at a stationary point of that
            model (for a pose error far from its target the CLIK rows are not the error's
            gradient: a rest at a position range switches them to the exact rows Jlog6 J,
            and the arm rests where the true error cannot fall, see docs/limits.md): with
            ``active_limits`` naming the limits that hold it, a minimum against them
            (``solver.move_to()`` reaches such targets by another way); without, a minimum of
            the error itself — a target out of reach, or one reachable only on another branch
            of the inverse kinematics — or a saddle that the escape tests
            after a window of stalled steps, over the next 2 n steps or so (one evaluation of
            the task rows a step; ``escaped`` is true on the steps of an escape it starts).
        levels: one :class:`LevelInfo` per priority level, top first: its error norm and
            the share of its task motion the step kept.
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
    rows_exceeded: tuple[tuple[str, float], ...] = ()
    outside_limits: tuple[str, ...] = ()
    stalled: bool = False
    levels: tuple[LevelInfo, ...] = ()

    @property
    def velocity_scale(self) -> float:
        return self.task_scale

    def __repr__(self) -> str:
        return (f"StepInfo(error_norm={self.error_norm:.3g}, "
                f"|dq|={float(np.linalg.norm(self.dq)):.3g} rad/s)")


def step_info(controller, stack, robot, J: np.ndarray, e: np.ndarray, q: np.ndarray,
              ff: np.ndarray | None, step: np.ndarray, owners, user, speed_by, fixed_gain,
              alpha: bool, escaped: bool) -> StepInfo:
    """The :class:`StepInfo` of a solver's last step from what its compiled ``controller``
    reports (its views are read, not kept) and the step's rows ``J``, error ``e``,
    configuration ``q``, feed-forward ``ff`` and displacement ``step`` (rad, m; its velocity
    ``step / dt`` is the step's ``dq``); ``owners`` names the limit of each user row,
    ``speed_by`` the limit behind each joint's speed bound; ``fixed_gain``: K as given (None
    for "auto", whose K the controller reports); ``alpha``: whether the method has SJT's
    scaling factors."""
    from .constraints import active_limits
    from .joint_ranges import outside

    c = controller
    names = robot.velocity_names
    sw, chain = stack.sqrt_weight, stack.chain
    J = stack.step_rows(J, e, c.exact_step)  # (the rows the step took)
    Jw = sw[:, None] * J * chain
    dq = step / c.dt
    active = active_limits(c, names, user, speed_by)
    joints = tuple(dict.fromkeys(joint for _, joint in active))
    index = {name: i for i, name in enumerate(names)}
    rows = stack.error_rows
    ffw = np.zeros(rows.size) if ff is None else (sw * ff)[rows]
    stalled = not escaped and makes_no_progress(Jw[rows], (sw * e)[rows], dq, ffw,
                                                c.stall_floor_sq)
    levels = []
    for k, ((begin, end, identity, _), (first, last)) in enumerate(
            zip(stack.levels, stack.level_errors, strict=True)):
        Jk = Jw[begin:end]
        asked = Jk @ (c.desired_top if k == 0 else c.desired)
        got = Jk @ dq
        size = float(asked @ asked)
        scale = 1.0 if size == 0.0 else min(max(float(got @ asked) / size, 0.0), 1.0)
        if identity:
            scale *= c.posture_share
        error = 0.0 if identity else float(np.linalg.norm(e[first:last]))
        levels.append(LevelInfo(k, error, scale))
    return StepInfo(
        error=np.array(stack.task_error(e), dtype=float), error_norm=math.sqrt(c.e_sq), dq=dq,
        gain=fixed_gain if fixed_gain is not None else c.gain,
        loop_bound=c.loop_bound if fixed_gain is None else 1.0, pose=stack.poses(),
        alpha=c.alpha.copy() if alpha else None, escaped=escaped,
        clamped=np.array([index[name] for name in joints], dtype=np.int64),
        clamped_joints=joints, task_scale=c.task_scale, active_limits=active,
        active_rows=tuple(sorted({owners[i] for i in c.rows_active})) if owners else (),
        limit_conflicts=tuple(names[j] for j in np.flatnonzero(c.torn)),
        rows_exceeded=user.exceeded(dq) if user is not None and owners else (),
        outside_limits=outside(robot.model, q, robot.lower_limits, robot.upper_limits,
                               robot.mimic_joints),
        stalled=stalled, levels=tuple(levels))
