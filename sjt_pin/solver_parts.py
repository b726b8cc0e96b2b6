"""The parts a :class:`~sjt_pin.solver.Solver` is built from, made from its options at
construction: the robot and method checked, the task, the built-in limits (position, speed,
acceleration, jerk) and the user's, the speed limits the user's limits cap, and the compiled
controller (``sjt_pin.kernels.Controller``) that runs the method and the constraint stage."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from . import kernels, model_measures
from .constraints import UserLimits
from .escape import SaddleEscape
from .gains import Gain
from .limits import AccelerationLimit, JerkLimit, Motion, PositionLimit, VelocityLimit
from .methods import Method
from .options import SolverOptions
from .robot import Robot
from .stack import TaskStack
from .tasks import PoseTask
from .tasks.pose import tasks_length


def check_parts(robot, method) -> None:
    """A solver's robot and method, checked at the door."""
    if not isinstance(robot, Robot):
        raise TypeError(f"robot must be a sjt_pin.Robot, got {type(robot).__name__}")
    if not isinstance(method, Method):
        raise TypeError(f"method must be a sjt_pin Method, got {type(method).__name__}")
    if robot.nv == 0:
        raise ValueError(f"robot {robot.name!r} has no moving joint: there is nothing to "
                         "solve for")


def options_task(options: SolverOptions):
    """The task(s) of ``options``: ``task``, or the pose task of length ``pose_length``."""
    if options.pose_length is None:
        return options.task
    if options.task is not None:
        raise ValueError("pose_length sets the length of the pose task made when task is "
                         "None; with a task of your own pass PoseTask(length=...)")
    return PoseTask(length=options.pose_length)


def speed_limits(velocity_limits, urdf: np.ndarray, nv: int) -> np.ndarray:
    """The speed limits a solver enforces (rad/s, m/s; inf for none)."""
    if velocity_limits is None or velocity_limits is True:
        return urdf.copy()
    if velocity_limits is False:
        return np.full(nv, np.inf)
    if isinstance(velocity_limits, (str, bytes)) or np.iscomplexobj(velocity_limits):
        raise ValueError(f"velocity_limits must be True, False or an array, "
                         f"got {velocity_limits!r}")
    vmax = np.asarray(velocity_limits, dtype=float)
    if vmax.shape != (nv,) or np.any(np.isnan(vmax)) or np.any(vmax <= 0):
        raise ValueError(f"velocity_limits must have shape ({nv},) with entries > 0 "
                         f"(rad/s or m/s; inf for none), got {velocity_limits!r}")
    return vmax


def braking_speeds(speeds: np.ndarray, revolute: np.ndarray) -> np.ndarray:
    """The URDF's speed limits ``speeds`` under acceleration limits: a revolute joint without
    one (a continuous joint whose URDF gives no ``velocity``) moves no faster than the
    fastest revolute joint that has one.

    Each joint brakes toward where the feedback sends it at its own acceleration limit, and
    that goal moves as the other joints move; a joint without a speed limit ran ahead of the
    limited ones and passed it: Bravo 7 (three such joints, the others at 0.5 rad/s; beyond
    reach, random acceleration and jerk limits) whipped its base to 9.7 rad/s and back, the
    error rising, for 30 s and more. Where no revolute joint has a limit, nothing changes."""
    limited = revolute & np.isfinite(speeds)
    if not limited.any():
        return speeds
    out = speeds.copy()
    out[revolute & ~limited] = speeds[limited].max()
    return out


class SolverLimits(NamedTuple):
    """A solver's limits: the built-in ones (``None`` where not enforced), the user's, and the
    motion state their bounds are evaluated on."""

    acceleration: AccelerationLimit | None
    jerk: JerkLimit | None
    position: PositionLimit | None
    velocity: VelocityLimit | None
    user: UserLimits | None
    motion: Motion


def solver_limits(robot: Robot, stack: TaskStack, opts: SolverOptions,
                  dt: float) -> SolverLimits:
    """The built-in limits (position, speed, acceleration, jerk) and the user's."""
    n = robot.nv
    moving = stack.chain > 0
    urdf = robot.velocity_limits
    acceleration = (None if opts.acceleration_limits is None
                               else AccelerationLimit(opts.acceleration_limits, n))
    jerk = None if opts.jerk_limits is None else JerkLimit(opts.jerk_limits, n)
    if jerk is not None and acceleration is None:
        raise ValueError("jerk_limits need acceleration_limits (the braking distance of a "
                         "jerk-limited stop depends on both)")
    position = PositionLimit(robot, moving, np.where(np.isfinite(urdf), urdf,
                                                     SaddleEscape.DEFAULT_SPEED))
    use = position.active if opts.position_limits is None else (
        bool(opts.position_limits) and position.active)
    position_limit = position if use else None
    speeds = speed_limits(opts.velocity_limits, urdf, n)
    if acceleration is not None and (opts.velocity_limits is None
                                     or opts.velocity_limits is True):
        speeds = braking_speeds(speeds, model_measures.revolute_velocities(robot.model))
    velocity = VelocityLimit(speeds) if np.isfinite(speeds).any() else None
    user = UserLimits(opts.limits, n) if opts.limits else None
    motion = Motion(robot.q0.copy(), np.zeros(n), np.zeros(n), dt,
                          None if acceleration is None
                          else acceleration.limits,
                          None if jerk is None else jerk.limits)
    return SolverLimits(acceleration, jerk, position_limit, velocity, user, motion)


def make_controller(robot: Robot, stack: TaskStack, method: Method, dt: float,
                    position: PositionLimit | None, accel: AccelerationLimit | None,
                    jerk: JerkLimit | None, escape: SaddleEscape | None, motion: Motion
                    ) -> tuple[kernels.Controller, bool]:
    """The compiled controller of a solver, and whether its method is one of the user's (the
    step passes its ``matrix`` function, which the controller calls with the first level's
    weighted rows); the ``motion`` state a user's limits read is bound to the controller's
    own."""
    params = method.parameters()
    matrix_method = params is None  # a method of your own: its matrix M(J) at each step
    if params is None:
        params = kernels.MethodParameters()  # the stage's metric of JT
        params.scaled, params.damped_feedback, params.damped_feedforward = False, False, True
    empty = np.zeros(0)
    controller = kernels.Controller(
        params, stack.dim, robot.nv, robot.nq, dt, stack.sqrt_weight,
        np.ones(stack.dim), stack.chain, stack.target_dim, stack.levels,
        np.full(robot.nv, np.inf),
        empty.astype(np.int64) if position is None else position.q_index,
        empty.astype(np.int64) if position is None else position.v_index,
        empty if position is None else position.lower,
        empty if position is None else position.upper,
        empty if position is None else position.recovery_speeds,
        None if accel is None else accel.limits, None if jerk is None else jerk.limits,
        -1.0 if escape is None else SaddleEscape.STALL_RATIO,
        # converged, not stalled: |e_w| below ERROR_FLOOR times the first level's length
        (SaddleEscape.ERROR_FLOOR * tasks_length(robot, stack.leading)) ** 2,
        stack.rank_scale)
    controller.set_log6_rows(stack.log6_rows)
    #: the motion state a user's limits read is the controller's own
    motion.dq, motion.ddq = controller.dq, controller.ddq
    return controller, matrix_method



def capped_speeds(user: UserLimits | None, dt: float, moving: np.ndarray,
                  velocity: VelocityLimit | None) -> tuple[np.ndarray, np.ndarray]:
    """The speed limits (rad/s, m/s; 0 for a joint no task moves) at period ``dt``, with the
    user's limits' caps, and the name of the limit that sets each."""
    speeds = np.where(moving, np.inf if velocity is None else velocity.limits, 0.0)
    by = np.full(speeds.size, "velocity", dtype=object)
    if user is not None:
        user.capped = set()
        for k, limit in enumerate(user.limits):
            caps = limit.speed_caps(dt)
            if caps is None:
                continue
            caps = np.asarray(caps, dtype=float)
            if caps.shape != speeds.shape or np.isnan(caps).any() or (caps <= 0).any():
                raise ValueError(f"{limit!r}.speed_caps() must return ({speeds.size},) "
                                 f"speeds > 0 (rad/s or m/s; inf for none), got {caps!r}")
            user.capped.add(k)  # (its bounds never go below its caps)
            tighter = moving & (caps < speeds)
            speeds = np.where(tighter, caps, speeds)
            by[tighter] = limit.name
    return speeds, by


def row_gains(stack: TaskStack, gain: Gain) -> np.ndarray:
    """The gain of each of ``stack``'s rows: the targets' error rows, then the others."""
    rows = gain.rows(stack.target_dim, stack.posture_dim)
    gains = np.empty(stack.dim)
    other = np.ones(stack.dim, dtype=bool)
    other[stack.error_rows] = False
    gains[stack.error_rows] = rows[:stack.target_dim]
    gains[other] = rows[stack.target_dim:]
    return gains
