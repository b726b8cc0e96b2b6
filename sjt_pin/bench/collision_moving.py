"""``sjt-pin bench collision``'s moving obstacles: a ball driven at the hand.

A 5 cm ball starts 45 cm beside the hand and is driven at it at 0.5 or 1 m/s until it stands
where the hand was; the arm holds its start pose (SJT, the solver's defaults), at 1 kHz and
100 Hz, with the robot's speed limits alone or with Franka-like acceleration and jerk limits
(:data:`ACCELERATION`, :data:`JERK`), and with the ball's velocity given to
``CollisionLimit.move`` or not. Each run reports the least distance of the ball to the robot
over the run, measured independently at every step (:class:`.collision.Checker`: coal on the
meshes, the ball where it is when the step starts), the steps below ``margin - 1 mm``, the
largest ratio of the returned speeds, accelerations and jerks (finite differences) to their
limits, the steps whose ``StepInfo.rows_exceeded`` says the rows could not all be kept, and
the time of the step with its ``move`` (process time, the checks left out).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from ..limits import CollisionLimit
from ..robot import Robot
from ..solvers import make_solver
from .collision import Checker, rates

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
    smooth: bool  # Franka-like acceleration and jerk limits
    told: bool  # the ball's velocity given to move()
    closest: float  # m, the least distance of the ball to the robot, meshes, independent
    below: int  # steps below margin - 1 mm
    speed_ratio: float  # the largest joint speed over its limit
    acceleration_ratio: float  # (nan without acceleration limits)
    jerk_ratio: float
    exceeded: int  # steps that reported rows_exceeded
    us_per_step: float  # move() and step(), process time


def franka_like(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Franka's acceleration and jerk limits for ``n`` joints (:data:`ACCELERATION`)."""
    pick = np.arange(n)
    pick[pick >= len(ACCELERATION)] = 0
    return ACCELERATION[pick], JERK[pick]


def drive(robot: Robot, speed: float, dt: float, smooth: bool = False, told: bool = True,
          travel: float = TRAVEL) -> MovingRow:
    """One run: the ball driven from ``travel`` (m) beside the hand of ``robot`` at its ``q0``
    at ``speed`` (m/s), at period ``dt`` (s)."""
    n = robot.nv
    q0 = robot.q0.copy()
    hand = robot.fk(q0)
    start = hand.translation + np.array([0.0, travel, 0.0])
    heading = np.array([0.0, -1.0, 0.0])
    ball = coal.Sphere(0.05)
    limit = CollisionLimit(robot, [(ball, pin.SE3(np.eye(3), start))], margin=MARGIN)
    checker = Checker(robot, [(ball, pin.SE3(np.eye(3), start))], limit.pair_names)
    options = {}
    if smooth:
        accelerations, jerks = franka_like(n)
        options = dict(acceleration_limits=accelerations, jerk_limits=jerks)
    solver = make_solver("sjt", robot, dt=dt, limits=[limit], **options)
    q, qs, closest, below, exceeded, spent = q0, [q0], np.inf, 0, 0, 0.0
    for k in range(int(round((travel / speed + HOLD) / dt))):
        moved = min(speed * k * dt, travel)
        pose = pin.SE3(np.eye(3), start + heading * moved)
        velocity = np.r_[heading * (speed if moved < travel else 0.0), 0.0, 0.0, 0.0]
        checker.move(0, pose)
        d = checker.closest(q)[0]
        closest, below = min(closest, d), below + (d < MARGIN - 1e-3)
        t0 = time.process_time()
        limit.move(0, pose, velocity=velocity if told else None)
        q = solver.step(q, hand)
        spent += time.process_time() - t0
        qs.append(q)
        exceeded += bool(solver.last.rows_exceeded)
    v, a, j = rates(robot.model, qs, dt)
    speed_ratio = float(np.max(np.abs(v) / robot.velocity_limits))
    acceleration_ratio = jerk_ratio = float("nan")
    if smooth:
        acceleration_ratio = float(np.max(np.abs(a) / options["acceleration_limits"]))
        jerk_ratio = float(np.max(np.abs(j) / options["jerk_limits"]))
    return MovingRow(robot.name, speed, 1.0 / dt, smooth, told, float(closest), int(below),
                     speed_ratio, acceleration_ratio, jerk_ratio, exceeded,
                     1e6 * spent / (len(qs) - 1))


def moving(robots=("panda", "ur5"), progress=None) -> list[MovingRow]:
    """Every robot at 0.5 and 1 m/s: at 1 kHz and 100 Hz with speed limits alone, at 1 kHz
    with Franka-like limits, each with the velocity told; and the 1 kHz runs without it."""
    rows = []
    for name in robots:
        robot = Robot.from_example(name)
        for speed in (0.5, 1.0):
            for dt, smooth, told in ((1e-3, False, True), (1e-2, False, True),
                                     (1e-3, True, True), (1e-3, False, False),
                                     (1e-3, True, False)):
                row = drive(robot, speed, dt, smooth, told)
                rows.append(row)
                if progress is not None:
                    progress(row)
    return rows


def moving_table(rows: list[MovingRow]) -> str:
    head = ("| robot | ball m/s | rate Hz | limits | velocity given | closest mm | steps < 9 mm "
            "| speed / limit | accel. / limit | jerk / limit | rows exceeded | us/step |\n"
            "|---|---|---|---|---|---|---|---|---|---|---|---|\n")
    body = "".join(
        f"| {r.robot} | {r.speed:g} | {r.rate:g} | {'Franka-like' if r.smooth else 'speed'} "
        f"| {'yes' if r.told else 'no'} | {1e3 * r.closest:.2f} | {r.below} "
        f"| {r.speed_ratio:.3f} | {_ratio(r.acceleration_ratio)} | {_ratio(r.jerk_ratio)} "
        f"| {r.exceeded} | {r.us_per_step:.0f} |\n" for r in rows)
    return head + body


def _ratio(x: float) -> str:
    return "-" if np.isnan(x) else f"{x:.2f}"
