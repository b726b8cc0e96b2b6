"""``sjt-pin bench collision``'s mesh obstacle: the hand pulled over a bumpy plate.

A 50 cm plate of 3 cm bumps (:func:`bumpy_plate`, a non-convex triangle mesh) lies 22 cm under
Panda's hand (its fingers 12 cm above the bumps' tops); the hand follows a line 20 cm
sideways and 17 cm down in 2 s and holds its end 1 s, with Franka-like acceleration and jerk
limits (:func:`.collision_moving.franka_like`). The limit keeps the mesh as its convex hull
(the default, ``convex=True``) or as given (``convex=False``). Each run reports the least
distance to the mesh itself (:class:`.collision.Checker`, every 5th step), the largest
acceleration and jerk over their limits, the steps that named joints in
``StepInfo.limit_conflicts``, the task error at the end and the step's process time.
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
from .collision import Checker, _line, rates
from .collision_moving import franka_like

DT = 1e-3
PULL, HOLD = 2.0, 1.0  # s


@dataclass
class MeshRow:
    convex: bool
    closest: float  # m, to the mesh, independent
    acceleration_ratio: float
    jerk_ratio: float
    conflicts: int  # steps naming joints in limit_conflicts
    unreported: int  # steps above the acceleration or jerk limit (1.001x) that named none
    final_error: float  # m and rad
    us_per_step: float  # process time


def bumpy_plate(size: float = 0.36, n: int = 24, height: float = 0.03,
                period: float = 0.08) -> coal.BVHModelOBBRSS:
    """A square plate of ``size`` (m) on an ``n`` x ``n`` grid whose height is ``height`` sin(2 pi
    x / period) sin(2 pi y / period): a non-convex triangle mesh, in its own frame."""
    xs = np.linspace(-size / 2, size / 2, n)
    X, Y = np.meshgrid(xs, xs)
    Z = height * np.sin(2 * np.pi * X / period) * np.sin(2 * np.pi * Y / period)
    corners = np.arange(n * n).reshape(n, n)[:-1, :-1].ravel()
    triangles = np.concatenate([np.column_stack([corners, corners + 1, corners + n + 1]),
                                np.column_stack([corners, corners + n + 1, corners + n])])
    mesh = coal.BVHModelOBBRSS()
    mesh.beginModel(len(triangles), n * n)
    mesh.addVertices(np.column_stack([X.ravel(), Y.ravel(), Z.ravel()]))
    mesh.addTriangles(triangles)
    mesh.endModel()
    return mesh


def pull(convex: bool, robot: Robot | None = None) -> MeshRow:
    """One run of the pull over the plate (``robot``: Panda by default)."""
    robot = robot or Robot.from_example("panda")
    n = robot.nv
    q = robot.q0.copy()
    start = robot.fk(q)
    plate = (bumpy_plate(), pin.SE3(np.eye(3), start.translation + np.array([0.1, 0.0, -0.22])))
    limit = CollisionLimit(robot, [plate], convex=convex)
    checker = Checker(robot, [plate], limit.pair_names)
    accelerations, jerks = franka_like(n)
    solver = make_solver("sjt", robot, dt=DT, limits=[limit], acceleration_limits=accelerations,
                         jerk_limits=jerks)
    end = pin.SE3(start.rotation, start.translation + np.array([0.0, 0.2, -0.17]))
    target = _line(start, end, PULL)
    qs, closest, reported, spent = [q], np.inf, [], 0.0
    for k in range(int(round((PULL + HOLD) / DT))):
        pose, velocity = target(k * DT)
        t0 = time.process_time()
        q = solver.step(q, pose, velocity)
        spent += time.process_time() - t0
        qs.append(q)
        reported.append(bool(solver.last.limit_conflicts))
        if k % 5 == 0:
            closest = min(closest, checker.closest(q)[0])
    _, a, j = rates(robot.model, qs, DT)
    above = (np.max(np.abs(a) / accelerations, axis=1) > 1.001) | (
        np.max(np.abs(j) / jerks, axis=1) > 1.001)
    return MeshRow(convex, float(closest), float(np.max(np.abs(a) / accelerations)),
                   float(np.max(np.abs(j) / jerks)), int(sum(reported)),
                   int(np.sum(above & ~np.array(reported))), solver.last.error_norm,
                   1e6 * spent / (len(qs) - 1))


def mesh_table(rows: list[MeshRow]) -> str:
    head = ("| obstacle kept as | closest mm (mesh) | accel. / limit | jerk / limit "
            "| steps with conflicts | unreported | final error | us/step |\n"
            "|---|---|---|---|---|---|---|---|\n")
    return head + "".join(
        f"| {'convex hull' if r.convex else 'mesh'} | {1e3 * r.closest:.2f} "
        f"| {r.acceleration_ratio:.2f} | {r.jerk_ratio:.2f} | {r.conflicts} | {r.unreported} "
        f"| {r.final_error:.3f} | {r.us_per_step:.0f} |\n" for r in rows)
