"""``sjt-pin bench collision``'s stream: a CollisionLimit beside acceleration and jerk limits.

Franka-like conditions on xArm7 (a robot no scene of :mod:`.collision` uses): 1 kHz, 10 rad/s^2
and 5,000 rad/s^3 on every joint, a new target every 0.5 s from a seeded draw of reachable
poses, every third one pushed 3x as far from the base (out of reach), self-collision on and,
in the second setting, a 5 cm ball beside the start; the limit's defaults (margin 10 mm,
influence 50 mm). Over 6 s for each of seeds 0-5 it counts the steps whose joint acceleration
or jerk (finite differences of the returned q) exceeds its limit, the worst ratios, the steps
above a limit that name no joint in ``StepInfo.limit_conflicts`` (the stage's promise: 0),
and the least distance of any checked pair, measured independently
(:class:`.collision.Checker`: coal on the meshes, every 5th step).
"""

from __future__ import annotations

from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from ..limits import CollisionLimit
from ..robot import Robot
from ..solvers import make_solver
from .collision import Checker, rates

DT = 1e-3
ACCELERATION, JERK = 10.0, 5000.0  # rad/s^2, rad/s^3 on every joint
SECONDS, EVERY = 6.0, 0.5  # s of each run, s between targets


@dataclass
class StreamRow:
    setting: str
    method: str
    steps: int  # steps in all runs
    over: int  # steps above the acceleration limit (> 1.001x)
    over_2x: int  # of which above 2x
    worst: float  # the largest ratio to the limit
    jerk_over: int  # steps above the jerk limit (> 1.001x)
    jerk_worst: float  # the largest ratio to it
    unreported: int  # such steps that name no joint in limit_conflicts
    closest: float  # m, every pair, independently


def _run(robot: Robot, method: str, ball: bool, seed: int, influence: float = 0.05):
    """One run: the configurations and whether each step reported a conflict."""
    rng = np.random.default_rng(seed)
    q = robot.q0.copy()
    start = robot.fk(q)
    obstacles = [(coal.Sphere(0.05), pin.SE3(np.eye(3), start.translation
                                             + np.array([0.0, 0.15, -0.05])))] if ball else []
    limit = CollisionLimit(robot, obstacles, self_collision=True, influence=influence)
    n = robot.nv
    solver = make_solver(method, robot, dt=DT, limits=[limit],
                         acceleration_limits=np.full(n, ACCELERATION),
                         jerk_limits=np.full(n, JERK))
    qs, reported = [q], []
    every = int(round(EVERY / DT))
    for k in range(int(round(SECONDS / DT))):
        if k % every == 0:
            target = robot.fk(robot.random_configuration(rng))
            if (k // every) % 3 == 2:
                target = pin.SE3(target.rotation, 3.0 * target.translation)
        q = solver.step(q, target)
        qs.append(q)
        reported.append(bool(solver.last.limit_conflicts))
    return np.array(qs), np.array(reported), limit, obstacles


def stream(methods=("sjt", "dls"), seeds=range(6), influence: float = 0.05, progress=None
           ) -> list[StreamRow]:
    """Both settings (self-collision; and a ball), each method, seeds 0-5 (module docstring),
    with the limit's ``influence`` (m; margin 10 mm)."""
    robot = Robot.from_example("xarm7")
    rows = []
    for ball in (False, True):
        checker = None  # (the same obstacles and pairs in every run of the setting)
        for method in methods:
            over = over_2x = unreported = steps = jerk_over = 0
            worst, jerk_worst, closest = 0.0, 0.0, np.inf
            for seed in seeds:
                qs, reported, limit, obstacles = _run(robot, method, ball, seed, influence)
                _, a, j = rates(robot.model, qs, DT)
                ratio = np.max(np.abs(a), axis=1) / ACCELERATION
                jerk = np.max(np.abs(j), axis=1) / JERK
                above = (ratio > 1.001) | (jerk > 1.001)
                steps += len(ratio)
                over += int((ratio > 1.001).sum())
                jerk_over += int((jerk > 1.001).sum())
                jerk_worst = max(jerk_worst, float(jerk.max()))
                over_2x += int((ratio > 2.0).sum())
                worst = max(worst, float(ratio.max()))
                unreported += int((above & ~reported).sum())
                if checker is None:
                    checker = Checker(robot, obstacles, limit.pair_names)
                closest = min(closest, min(checker.closest(q)[0] for q in qs[::5]))
            row = StreamRow("self-collision + ball" if ball else "self-collision", method,
                            steps, over, over_2x, worst, jerk_over, jerk_worst, unreported,
                            closest)
            if progress is not None:
                progress(row)
            rows.append(row)
    return rows


def stream_table(rows: list[StreamRow]) -> str:
    """The rows as a markdown table (steps, ratios to the limits, distances in mm)."""
    lines = ["| xArm7 stream | method | steps above the acceleration limit | of them > 2x | "
             "worst | above the jerk limit | worst | unreported | closest (mm) |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r.setting} | {r.method.upper()} | {r.over} of {r.steps} "
                     f"({100 * r.over / r.steps:.1f} %) | {r.over_2x} | {r.worst:.1f}x | "
                     f"{r.jerk_over} | {r.jerk_worst:.1f}x | {r.unreported} | "
                     f"{1000 * r.closest:.2f} |")
    return "\n".join(lines)
