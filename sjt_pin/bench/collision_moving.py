"""``sjt-pin bench collision``'s moving obstacles: a ball driven at the hand.

A 5 cm ball starts 45 cm beside the hand and is driven at it at 0.5 or 1 m/s until it stands
where the hand was; the arm holds its start pose (SJT, the solver's defaults), at 1 kHz and
100 Hz, with the robot's speed limits alone or with Franka-like acceleration and jerk limits
(:data:`ACCELERATION`, :data:`JERK`), and with the ball's velocity given to
``CollisionLimit.move``, its poses time-stamped instead (the limit differentiates them), or
neither. Each run reports the least distance of the ball to the robot
over the run, measured independently at every step (:class:`.collision.Checker`: coal on the
meshes, the ball where it is when the step starts), the steps below ``margin - 1 mm``, the
largest ratio of the returned speeds, accelerations and jerks (finite differences) to their
limits, the steps whose ``StepInfo.rows_exceeded`` says the rows could not all be kept, and
the time of the step with its ``move`` (process time, the checks left out). pink's and mink's
runs beside the same ball are in :mod:`.collision_peers` and :mod:`.collision_mink`.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from ..limits import CollisionLimit
from ..robot import Robot
from ..solvers import make_solver
from .collision import Checker, dash, failed_at, rates, run_steps

MARGIN = 0.01
TRAVEL = 0.45  # m the ball comes from
HOLD = 0.5  # s the run goes on after the ball stops
#: Franka's joint acceleration and jerk limits (rad/s^2, rad/s^3; joints past the seventh take
#: the first joint's)
ACCELERATION = np.array([15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0])
JERK = np.array([7500.0, 3750.0, 5000.0, 6250.0, 7500.0, 10000.0, 10000.0])


@dataclass
class MovingRow:
    robot: str
    speed: float  # m/s of the ball
    rate: float  # Hz
    smooth: bool  # Franka-like acceleration and jerk limits (pink: its acceleration limit)
    told: bool | str  # the ball's velocity given to move() (True), "time": its time stamps
    closest: float  # m, the least distance of the ball to the robot, meshes, independent
    below: int  # steps below margin - 1 mm
    speed_ratio: float  # the largest joint speed over its limit
    acceleration_ratio: float  # (nan without acceleration limits)
    jerk_ratio: float
    exceeded: int | None  # steps that reported rows_exceeded (None: a peer has no such report)
    us_per_step: float  # move() and step(), process time
    method: str = "SJT"
    failed_at: float = float("nan")  # s: when the solver failed and the run ended (nan: never)


def franka_like(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Franka's acceleration and jerk limits for ``n`` joints (:data:`ACCELERATION`)."""
    pick = np.arange(n)
    pick[pick >= len(ACCELERATION)] = 0
    return ACCELERATION[pick], JERK[pick]


@dataclass
class Ball:
    """One run's ball: its path (the pose and the velocity, a 6-vector in m/s and rad/s, at
    each step), the hand's pose at ``q0`` (the arm's target) and the independent check."""

    speed: float  # m/s
    path: list[tuple[pin.SE3, np.ndarray]]
    hand: pin.SE3
    shape: coal.Sphere
    checker: Checker | None = None

    @property
    def obstacles(self) -> list:
        """The ball at its first pose, as ``CollisionLimit`` takes obstacles."""
        return [(self.shape, self.path[0][0])]


def ball(robot: Robot, speed: float, dt: float, travel: float = TRAVEL) -> Ball:
    """The ball driven from ``travel`` (m) beside the hand of ``robot`` at its ``q0`` at
    ``speed`` (m/s) until it stands where the hand is, then :data:`HOLD` s at rest, at period
    ``dt`` (s)."""
    hand = robot.fk(robot.q0)
    start = hand.translation + np.array([0.0, travel, 0.0])
    heading = np.array([0.0, -1.0, 0.0])
    path = []
    for k in range(int(round((travel / speed + HOLD) / dt))):
        moved = min(speed * k * dt, travel)
        path.append((pin.SE3(np.eye(3), start + heading * moved),
                     np.r_[heading * (speed if moved < travel else 0.0), 0.0, 0.0, 0.0]))
    return Ball(speed, path, hand, coal.Sphere(0.05))


def drive(robot: Robot, speed: float, dt: float, smooth: bool = False,
          told: bool | str = True, travel: float = TRAVEL) -> MovingRow:
    """One run: the ball driven from ``travel`` (m) beside the hand of ``robot`` at its ``q0``
    at ``speed`` (m/s), at period ``dt`` (s); ``told``: its velocity given to ``move``
    (True), its poses time-stamped (``"time"``: the limit differentiates them) or neither
    (False)."""
    driven = ball(robot, speed, dt, travel)
    limit = CollisionLimit(robot, driven.obstacles, margin=MARGIN)
    driven.checker = Checker(robot, driven.obstacles, limit.pair_names)
    options = {}
    if smooth:
        accelerations, jerks = franka_like(robot.nv)
        options = dict(acceleration_limits=accelerations, jerk_limits=jerks)
    solver = make_solver("sjt", robot, dt=dt, limits=[limit], **options)
    exceeded: list[bool] = []
    ticks = itertools.count()  # (the step's index: its pose's time stamp over dt)

    def step(q, pose, velocity):
        if told == "time":
            limit.move(0, pose, time=next(ticks) * dt)
        else:
            limit.move(0, pose, velocity=velocity if told else None)
        return solver.step(q, driven.hand)

    qs, us = run_steps(robot.q0, driven.path, step,
                       after=lambda: exceeded.append(bool(solver.last.rows_exceeded)))
    return moving_row(robot, driven, dt, smooth, told, qs, us, sum(exceeded), "SJT")


def moving_row(robot: Robot, driven: Ball, dt: float, smooth: bool, told: bool | str,
               qs: np.ndarray, us: float, exceeded: int | None, method: str) -> MovingRow:
    """The row of a run whose configurations are ``qs`` (at most one more than the ball's
    path: fewer if the solver failed) and CPU time ``us`` per step: the distances are checked
    with the ball where it was when each step started (``driven.checker``, meshes), the
    ratios are those of :func:`.collision.rates` to the robot's speed limits and
    :func:`franka_like`."""
    assert driven.checker is not None
    closest, below = np.inf, 0
    for q, (pose, _) in zip(qs, driven.path, strict=False):
        driven.checker.move(0, pose)
        d = driven.checker.closest(q)[0]
        closest, below = min(closest, d), below + (d < MARGIN - 1e-3)
    v, a, j = rates(robot.model, qs, dt)
    speed_ratio = float(np.max(np.abs(v) / robot.velocity_limits, initial=0.0))
    acceleration_ratio = jerk_ratio = float("nan")
    if smooth:
        accelerations, jerks = franka_like(robot.nv)
        acceleration_ratio = float(np.max(np.abs(a) / accelerations, initial=0.0))
        jerk_ratio = float(np.max(np.abs(j) / jerks, initial=0.0))
    return MovingRow(robot.name, driven.speed, 1.0 / dt, smooth, told, float(closest), int(below),
                     speed_ratio, acceleration_ratio, jerk_ratio, exceeded, us, method,
                     failed_at(qs, len(driven.path), dt))


def sweep(robots: Sequence[str], settings: Sequence[tuple],
          run: Callable[..., MovingRow],
          progress: Callable[[MovingRow], object] | None = None) -> list[MovingRow]:
    """``run(robot, speed, *setting)`` for every robot (example-robot-data names), the ball
    at 0.5 and 1 m/s, and every setting (the run's further arguments)."""
    rows = []
    for name in robots:
        robot = Robot.from_example(name)
        for speed in (0.5, 1.0):
            for setting in settings:
                rows.append(run(robot, speed, *setting))
                if progress is not None:
                    progress(rows[-1])
    return rows


def moving(robots=("panda", "ur5"), progress=None) -> list[MovingRow]:
    """Every robot at 0.5 and 1 m/s: at 1 kHz and 100 Hz with speed limits alone, at 1 kHz
    with Franka-like limits, each with the velocity told; the last with time-stamped poses
    instead; and the 1 kHz runs without either (``(dt, smooth, told)`` of :func:`drive`)."""
    return sweep(robots, ((1e-3, False, True), (1e-2, False, True), (1e-3, True, True),
                          (1e-3, True, "time"), (1e-3, False, False), (1e-3, True, False)),
                 drive, progress)


def moving_table(rows: list[MovingRow]) -> str:
    """The rows as a markdown table (distances in mm; "failed at" in s)."""
    head = ("| robot | method | ball m/s | rate Hz | limits | velocity given | closest mm "
            "| steps < 9 mm | speed / limit | accel. / limit | jerk / limit | rows exceeded "
            "| failed at | us/step |\n"
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n")
    body = "".join(
        f"| {r.robot} | {r.method} | {r.speed:g} | {r.rate:g} "
        f"| {'Franka-like' if r.smooth else 'speed'} "
        f"| {'time stamps' if r.told == 'time' else 'yes' if r.told else 'no'} "
        f"| {1e3 * r.closest:.2f} | {r.below} | {r.speed_ratio:.3f} "
        f"| {dash(r.acceleration_ratio)} | {dash(r.jerk_ratio)} "
        f"| {dash(r.exceeded, 'd')} | {dash(r.failed_at)} "
        f"| {r.us_per_step:.0f} |\n" for r in rows)
    return head + body


