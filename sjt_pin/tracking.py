"""Run a solver along a trajectory and log what happened.

At each sample time t_k the solver is given the configuration reached so far, the desired pose
x_d(t_k) and velocity x_dot_d(t_k), as in the paper's eq. (5): the logged error
``e_k = x_d(t_k) - x(q_k)`` is the one the CLIK law acts on.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .solver import Solver
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

    A diverging run (non-finite state, ``max_step`` or ``max_error`` exceeded) stops there with
    ``diverged=True`` and the reason, instead of raising.
    """
    if not isinstance(solver, Solver):
        raise TypeError(f"solver must be a sjt_pin Solver, got {type(solver).__name__}")
    if len(solver.stack.targeted) != 1:
        raise TypeError("track drives one task frame; step() takes several (see the README)")
    if not isinstance(trajectory, Trajectory):
        raise TypeError(f"trajectory must be a Trajectory, got {type(trajectory).__name__}")
    max_step = positive(max_step, "max_step", "rad")
    max_error = positive(max_error, "max_error", "task units")
    q = solver.robot.check_q(q0, "q0").copy()
    if trajectory.position_only:  # no rotation= given: hold the frame's start orientation
        frame = solver.stack.task.frame_id
        trajectory = trajectory.holding(solver.robot.fk(q, frame if frame >= 0 else None).rotation)
    dt = solver.dt
    times = trajectory.times(dt, duration)
    positions_d, rotations_d, velocities_d = trajectory.samples(times)
    n, nq, nv, m = times.size, solver.robot.nq, solver.robot.nv, solver.stack.target_dim
    qs, steps = np.empty((n, nq)), np.empty((n, nv))
    positions, errors, norms = np.empty((n, 3)), np.empty((n, m)), np.empty(n)
    scales = np.ones(n)
    target = pin.SE3(np.array(rotations_d[0]), np.array(positions_d[0]))
    task = solver.stack.task
    step = solver.step
    diverged, reason, k = False, "", -1
    with np.errstate(all="ignore"):
        for k in range(n):
            target.translation = positions_d[k]
            target.rotation = rotations_d[k]
            try:
                q_next = step(q, target, velocities_d[k] if feedforward else None)
            except ValueError as exc:  # a non-finite state or error: the run blew up
                if np.all(np.isfinite(q)):
                    raise
                diverged, reason = True, f"non-finite state at t = {times[k]:.4g} s ({exc})"
                break
            qs[k], steps[k], errors[k] = q, solver.displacement, solver.error
            norms[k] = norm = solver.error_norm
            scales[k] = solver.task_scale
            positions[k] = task.placement.translation  # type: ignore[union-attr]
            if not norm < max_error:
                diverged, reason = True, (f"error above {max_error:g} at t = {times[k]:.4g} s"
                                          if np.isfinite(norm) else
                                          f"non-finite state at t = {times[k]:.4g} s")
                break
            q = q_next
    end = k + 1
    # a step above max_step ends the run there (tested once, after the loop)
    jumps = np.flatnonzero(np.abs(steps[:end]).max(axis=1, initial=0.0) > max_step)
    if jumps.size:
        end = int(jumps[0]) + 1
        diverged, reason = True, (f"a joint moved more than {max_step:g} in one step at "
                                  f"t = {times[end - 1]:.4g} s")
    return TrackingLog(
        t=times[:end], q=qs[:end], dq=steps[:end] / dt, position=positions[:end],
        target=np.array(positions_d[:end]), error=errors[:end], error_norm=norms[:end],
        task_scale=scales[:end],
        diverged=diverged, reason=reason, method=solver.method.name, dt=dt, gain=solver.gain)
