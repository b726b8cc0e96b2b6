"""``sjt-pin bench collision``'s blocked targets: does an arm come to rest behind an obstacle?

:func:`blocked_scene` draws a random start within the joint ranges, a reachable end pose (a
joint-space step of up to 0.8 rad per joint, reached in 1 s along a line) and an obstacle of a
random kind (sphere, box, capsule, cylinder) around that pose, its centre within a few mm of
the target's origin, at least 2 cm from the robot at the start: the hand can only come as close
as the margin lets it. :func:`blocked` runs such scenes on arms no other
collision benchmark uses (UR3 and UR5 with their grippers, TALOS's arm), SJT and DLS with their
defaults, self-collision on, and acceleration limits of 15 rad/s² alone or with 7,500 rad/s³,
for 8 s at 1 kHz (the target stops after 1 s). Each run reports when the arm came to rest for
good (every joint below 1e-6 rad/s from then to the end; ``nan`` if it still moves at 8 s: a
pause that ends before the run does is not rest), the RMS joint speed over the last second, the
least distance of any checked pair (measured independently, :class:`.collision.Checker`: coal
on the meshes, every 5th step), the largest finite-difference acceleration and jerk over their
limits, and the steps whose ``StepInfo.limit_conflicts`` says a smoothness limit gave way to
the rows (the margin wins).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from ..limits import CollisionLimit
from ..limits.collision import CollisionError
from ..robot import Robot
from ..solvers import make_solver
from .collision import Checker, dash, line_path, rates

DT = 1e-3
MARGIN = 0.01
SECONDS = 8.0
ACCELERATION = 15.0  # rad/s^2, every joint
JERK = 7500.0  # rad/s^3, every joint
ARMS = ("ur3_gripper", "ur5_gripper", "talos_arm")
STILL = 1e-6  # rad/s: a joint slower than this is at rest


def blocked_scene(robot: Robot, rng: np.random.Generator
                  ) -> tuple[np.ndarray, pin.SE3, Callable, tuple]:
    """``(q0, end, target, obstacle)``: a start, the end pose, ``target(t) -> (pose,
    velocity)`` the line from the start's pose to it in 1 s, and ``(shape, pose)`` the obstacle
    around it (module docstring)."""
    model = robot.model
    lower, upper = model.lowerPositionLimit, model.upperPositionLimit
    middle, half = (lower + upper) / 2, np.minimum((upper - lower) / 2, np.pi)
    while True:
        q0 = middle + rng.uniform(-0.5, 0.5, model.nq) * half
        q1 = np.clip(q0 + rng.uniform(-0.8, 0.8, model.nq), lower, upper)
        start, end = robot.fk(q0), robot.fk(q1)
        kinds = [coal.Sphere(rng.uniform(0.04, 0.08)), coal.Box(*rng.uniform(0.06, 0.16, 3)),
                 coal.Capsule(rng.uniform(0.03, 0.05), rng.uniform(0.05, 0.15)),
                 coal.Cylinder(rng.uniform(0.03, 0.06), rng.uniform(0.05, 0.15))]
        shape = kinds[rng.integers(len(kinds))]
        pose = pin.SE3(pin.exp3(rng.normal(size=3)),
                       end.translation + rng.normal(size=3) * 0.01)
        try:
            probe = CollisionLimit(robot, [(shape, pose)], self_collision=True)
            probe.check(q0)
        except CollisionError:
            continue
        if min(d.distance for d in probe.distances(q0)) >= 0.02:
            return q0, end, line_path(start, end, 1.0), (shape, pose)


@dataclass
class BlockedRow:
    """One run (module docstring); ``jerk`` (rad/s^3) is nan without a jerk limit."""

    robot: str
    seed: int
    method: str
    jerk: float
    rest_at: float  # s, nan: still moving at the end
    rest: float  # RMS joint speed over the last second, rad/s
    min_distance: float  # m, any checked pair, meshes, independent
    acceleration: float  # largest finite-difference acceleration / limit
    jerk_ratio: float  # largest finite-difference jerk / limit (nan without one)
    yielded: int  # steps that reported limit_conflicts


def blocked_run(robot: Robot, seed: int, method: str, jerk: float | None) -> BlockedRow:
    """The blocked scene ``seed`` of ``robot`` (:func:`blocked_scene`) for :data:`SECONDS`."""
    q0, _, target, obstacle = blocked_scene(robot, np.random.default_rng(seed))
    limit = CollisionLimit(robot, [obstacle], self_collision=True, margin=MARGIN)
    smooth = {} if jerk is None else {"jerk_limits": np.full(robot.nv, jerk)}
    solver = make_solver(method, robot, dt=DT, limits=[limit],
                         acceleration_limits=np.full(robot.nv, ACCELERATION), **smooth)
    q, qs, yielded = q0.copy(), [q0.copy()], 0
    for k in range(int(round(SECONDS / DT))):
        pose, velocity = target(k * DT)
        q = solver.step(q, pose, velocity)
        qs.append(q)
        yielded += bool(solver.last.limit_conflicts)
    qs = np.array(qs)
    v, a, j = rates(robot.model, qs, DT)
    moving = np.flatnonzero(np.abs(v).max(axis=1) >= STILL)
    rest_at = float("nan") if moving.size and moving[-1] == len(v) - 1 else (
        float(moving[-1] + 1) * DT if moving.size else 0.0)
    last = v[-int(round(1.0 / DT)):]
    checker = Checker(robot, [obstacle], limit.pair_names)
    return BlockedRow(robot.name, seed, method.upper(),
                      float("nan") if jerk is None else float(jerk), rest_at,
                      float(np.sqrt(np.mean(last ** 2))),
                      min(checker.closest(x)[0] for x in qs[::5]),
                      float(np.abs(a).max() / ACCELERATION),
                      float("nan") if jerk is None else float(np.abs(j).max() / jerk), yielded)


def blocked(arms=ARMS, seeds=range(5), methods=("sjt", "dls"), jerks=(None, JERK),
            progress=None) -> list[BlockedRow]:
    """Every arm, seed, method and jerk setting of the module docstring."""
    rows = []
    for name in arms:
        robot = Robot.from_example(name)
        for seed in seeds:
            for method in methods:
                for jerk in jerks:
                    rows.append(blocked_run(robot, seed, method, jerk))
                    if progress:
                        progress(rows[-1])
    return rows


def blocked_table(rows: list[BlockedRow]) -> str:
    out = ["| robot | seed | method | jerk limit | at rest from [s] | RMS speed, last 1 s "
           "[rad/s] | min distance [mm] | acceleration / limit | jerk / limit | yielded |",
           "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r.robot} | {r.seed} | {r.method} | {dash(r.jerk, '.0f')} | "
                   f"{dash(r.rest_at, '.2f')} | {r.rest:.1e} | {1e3 * r.min_distance:.1f} | "
                   f"{r.acceleration:.3f} | {dash(r.jerk_ratio, '.3f')} | {r.yielded} |")
    return "\n".join(out)
