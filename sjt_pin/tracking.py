"""Run a solver along a trajectory and log what happened.

At each sample time t_k the solver is given the configuration reached so far, the desired pose
x_d(t_k) and velocity x_dot_d(t_k), as in the paper's eq. (5): the logged error
``e_k = x_d(t_k) - x(q_k)`` is the one the CLIK law acts on.
"""

from __future__ import annotations

import itertools
import warnings
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .kinematics import Kinematics
from .solver import Solver
from .tasks import OrientationTask, PoseTask, PositionTask, RelativePoseTask, Task
from .trajectories import Trajectory
from .validation import positive


@dataclass
class TrackingLog:
    """Arrays of one tracking run, one row per control period actually simulated.

    Attributes:
        t: sample times (N,) in s.
        q: configuration at which each error was measured (N, nq).
        dq: joint velocity commanded at each step (N, nv), rad/s or m/s.
        position: end-effector (task frame) position (N, 3) in m, world axes.
        target: desired position (N, 3) in m.
        error: task error vectors (N, m) in task units (m, rad).
        error_norm: their norms (N,).
        task_scale: the factor (N,) by which the constraint stage scaled each step's task
            velocity (1: the whole task; below 1: a limit kept the path from being followed
            at full speed — see ``StepInfo.active_limits`` for which).
        diverged: the run was stopped because the state blew up (see ``track``).
        reason: why it was stopped, empty when it ran to the end.
        method: the solver's method name; ``dt`` its period (s); ``gain`` its gain setting.
    """

    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    position: np.ndarray
    target: np.ndarray
    error: np.ndarray
    error_norm: np.ndarray
    task_scale: np.ndarray | None = None
    diverged: bool = False
    reason: str = ""
    method: str = ""
    dt: float = 0.0
    gain: object = "auto"  #: the solver's gain setting: a number, per row, "auto" or a Gain

    @property
    def max_error(self) -> float:
        """Largest task error norm over the run (inf if it diverged)."""
        if self.diverged or self.error_norm.size == 0:
            return float("inf")
        return float(self.error_norm.max())

    @property
    def rms_error(self) -> float:
        """Root mean square of the task error norm over the run (inf if it diverged)."""
        if self.diverged or self.error_norm.size == 0:
            return float("inf")
        return float(np.sqrt(np.mean(self.error_norm**2)))

    @property
    def max_joint_speed(self) -> float:
        """Largest absolute joint velocity commanded (rad/s or m/s)."""
        return float(np.abs(self.dq).max()) if self.dq.size else 0.0

    def __len__(self) -> int:
        return self.t.size


def track(
    solver: Solver,
    trajectory: Trajectory,
    q0,
    *,
    duration: float | None = None,
    max_step: float = np.pi,
    max_error: float = 1e3,
    feedforward: bool = True,
) -> TrackingLog:
    """Track ``trajectory`` with ``solver`` from configuration ``q0``.

    Args:
        duration: simulated time in s (default: the trajectory's; longer keeps commanding
            its final pose).
        max_step: the run counts as diverged when one step moves a joint by more than this
            (rad or m); the default, half a turn per control period, is no motion any robot makes.
        max_error: the run counts as diverged when the task error norm exceeds this (m, rad).
        feedforward: pass the trajectory's velocity x_dot_d to the solver; False runs the
            feedback term K e alone (to show what the feed-forward buys).

    A position-only ``Line`` or ``Circle`` (made without ``rotation=``) is tracked holding the
    task frame's orientation at ``q0``.

    A diverging run (non-finite state, ``max_step`` or ``max_error`` exceeded) is logged up to
    there, with ``diverged=True`` and the reason, instead of raising (``max_error`` is tested
    every 1024 steps and ``max_step`` after the run, not per step: the solver may have stepped
    past the log's end).
    """
    max_step, max_error = _check(solver, trajectory, max_step, max_error)
    q = solver.robot.check_q(q0, "q0").copy()
    if trajectory.position_only:  # no rotation= given: hold the frame's start orientation
        frame = solver.stack.task.frame_id
        trajectory = trajectory.holding(solver.robot.fk(q, frame if frame >= 0 else None).rotation)
    times = trajectory.times(solver.dt, duration)
    _warn_if_it_jumps(solver, trajectory, q)
    run = _Run(solver, times.size)
    end, reason = run.go(q, times, *trajectory.samples(times), feedforward, max_error)
    # a step above max_step ends the run there (tested once, after the loop)
    jumps = np.flatnonzero(np.abs(run.steps[:end]).max(axis=1, initial=0.0) > max_step)
    if jumps.size:
        end = int(jumps[0]) + 1
        reason = (f"a joint moved more than {max_step:g} in one step at "
                  f"t = {times[end - 1]:.4g} s")
    return run.log(times, end, reason)


#: a path whose first target is farther than this from the task frame (m) gets a warning
JUMP_WARNING = 1e-3


def _warn_if_it_jumps(solver: Solver, trajectory: Trajectory, q: np.ndarray) -> None:
    """Warn when the trajectory's first target position lies away from the task frame at
    ``q`` (along the axes a position task tracks): the target then jumps at t = 0, a circle
    centred on the wrong side of the hand by its diameter."""
    task = solver.stack.task
    if isinstance(task, PositionTask):
        rows = task._rows
    elif isinstance(task, PoseTask):
        rows = np.arange(3)
    else:
        return
    frame = task.frame_id if task.frame_id >= 0 else None
    first = trajectory.sample(0.0)[0].translation
    here = solver.robot.fk(q, frame).translation
    gap = float(np.linalg.norm((first - here)[rows]))
    if gap > JUMP_WARNING:
        name = solver.robot.model.frames[solver.robot.frame_id(frame or
                                                              solver.robot.ee_frame)].name
        warnings.warn(
            f"the trajectory starts {gap:.3g} m from frame {name!r} at q0, so the target jumps "
            "there at t = 0 (a Circle starts at center + radius along its plane's first axis, "
            "or at start_angle; a Line at start)", UserWarning, stacklevel=3)


def _check(solver, trajectory, max_step, max_error) -> tuple[float, float]:
    """The arguments of :func:`track`, checked once at the door."""
    if not isinstance(solver, Solver):
        raise TypeError(f"solver must be a sjt_pin Solver, got {type(solver).__name__}")
    if len(solver.stack.targeted) != 1:
        raise TypeError("track drives one task frame; step() takes several (docs/tasks.md, "
                        "'Several frames')")
    if not isinstance(trajectory, Trajectory):
        raise TypeError(f"trajectory must be a Trajectory, got {type(trajectory).__name__}")
    return (positive(max_step, "max_step", "rad"),
            positive(max_error, "max_error", "task units"))


#: steps between two checks of the logged error against ``max_error``: a run that exceeds it
#: is cut at its first step above it, having made at most this many more
_BLOCK = 1024


class _Run:
    """The preallocated arrays of one :func:`track` run and its loop."""

    def __init__(self, solver: Solver, n: int):
        robot, m = solver.robot, solver.stack.target_dim
        self.solver = solver
        self.qs, self.steps = np.empty((n, robot.nq)), np.empty((n, robot.nv))
        self.positions = np.empty((n, 3))
        self.errors, self.norms, self.scales = np.empty((n, m)), np.empty(n), np.ones(n)
        self.positions_d = np.empty((n, 3))

    def go(self, q, times, positions_d, rotations_d, velocities_d, feedforward: bool,
           max_error: float) -> tuple[int, str]:
        """Step along the samples; returns how many steps were logged and why the run stopped
        early ("" when it did not). The error norms are checked after every :data:`_BLOCK`
        steps."""
        solver, step = self.solver, self.solver.step
        task, displacement = solver.stack.task, solver.displacement  # (the same array always)
        frame = _frame_position(task, solver.stack.kinematics)
        qs, steps, errors, scales = self.qs, self.steps, self.errors, self.scales
        positions = self.positions
        positions_d, rotations_d, velocities_d = (np.asarray(x, dtype=float) for x in (
            positions_d, rotations_d, velocities_d))
        self.positions_d[:] = positions_d
        target = pin.SE3(np.array(rotations_d[0]), np.array(positions_d[0]))
        # one orientation for every sample (a Line's or a Circle's, broadcast): set once
        rotations = (itertools.repeat(None) if rotations_d.strides[0] == 0
                     else iter(rotations_d))
        velocities = iter(velocities_d) if feedforward else itertools.repeat(None)
        k = 0
        with np.errstate(all="ignore"):
            for start in range(0, times.size, _BLOCK):
                try:
                    block = positions_d[start:start + _BLOCK]  # (first: zip stops at its end)
                    for position, rotation, velocity in zip(block, rotations, velocities,
                                                            strict=False):
                        target.translation = position
                        if rotation is not None:
                            target.rotation = rotation
                        q_next = step(q, target, velocity)
                        qs[k], steps[k], errors[k] = q, displacement, solver.error
                        positions[k] = (task.placement.translation  # type: ignore[union-attr]
                                        if frame is None else frame)
                        scales[k] = solver.task_scale
                        k += 1
                        q = q_next
                except ValueError as exc:  # a non-finite state or error: the run blew up
                    end, reason = self._above(times, start, k, max_error)
                    if reason:
                        return end, reason
                    if np.all(np.isfinite(q)):
                        raise
                    return k, f"non-finite state at t = {times[k]:.4g} s ({exc})"
                end, reason = self._above(times, start, k, max_error)
                if reason:
                    return end, reason
        return k, ""

    def _above(self, times: np.ndarray, start: int, stop: int, max_error: float
               ) -> tuple[int, str]:
        """The norms of the errors logged from ``start`` to ``stop``; the rows to keep and why
        when one is not below ``max_error`` (``(stop, "")`` when none)."""
        norms = self.norms[start:stop]
        _norms(self.errors[start:stop], norms)
        above = np.flatnonzero(~(norms < max_error))
        if not above.size:
            return stop, ""
        k = start + int(above[0])
        return k + 1, (f"error above {max_error:g} at t = {times[k]:.4g} s"
                       if np.isfinite(self.norms[k]) else
                       f"non-finite state at t = {times[k]:.4g} s")

    def log(self, times: np.ndarray, end: int, reason: str) -> TrackingLog:
        """The first ``end`` rows as a :class:`TrackingLog`."""
        solver = self.solver
        return TrackingLog(
            t=times[:end], q=self.qs[:end], dq=self.steps[:end] / solver.dt,
            position=self.positions[:end], target=self.positions_d[:end],
            error=self.errors[:end], error_norm=self.norms[:end], task_scale=self.scales[:end],
            diverged=bool(reason), reason=reason, method=solver.method.name, dt=solver.dt,
            gain=solver.gain)


#: the built-in tasks' ``compute``: each sets ``placement`` to ``Kinematics.placement`` of its
#: ``frame_id``, the pose Pinocchio's data holds for that frame
_PLACED = (PoseTask.compute, PositionTask.compute, OrientationTask.compute,
           RelativePoseTask.compute)


def _frame_position(task: Task, kinematics: Kinematics) -> np.ndarray | None:
    """The task frame's world position (3,) as a view on Pinocchio's data, which every step
    updates in place (one copy logs it, instead of a ``pin.SE3`` and its translation made per
    step); ``None`` for a task of the user's own, whose ``placement`` is read per step."""
    if type(task).compute not in _PLACED or task.frame_id < 0:
        return None
    return kinematics.data.oMf[task.frame_id].translation


def _norms(errors: np.ndarray, out: np.ndarray) -> None:
    """The row norms of ``errors`` into ``out``, summed in the order the step's kernel sums
    them (so each is ``solver.error_norm`` of its step, bitwise)."""
    np.multiply(errors[:, 0], errors[:, 0], out=out)
    for i in range(1, errors.shape[1]):
        out += errors[:, i] * errors[:, i]
    np.sqrt(out, out=out)
