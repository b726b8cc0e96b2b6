"""``sjt-pin bench collision``'s mesh obstacle: the hand pulled over a bumpy plate.

A 50 cm plate of 3 cm bumps (:func:`bumpy_plate`, a non-convex triangle mesh) lies 22 cm under
Panda's hand (its fingers 12 cm above the bumps' tops); the hand follows a line 20 cm
sideways and 17 cm down in 2 s and holds its end 1 s, with Franka-like acceleration and jerk
limits (:func:`.collision_moving.franka_like`). The limit keeps the mesh as its convex hull
(the default, ``convex=True``) or as given (``convex=False``). Each run reports the least
distance to the mesh itself (:class:`.collision.Checker`, every 5th step), the largest
acceleration and jerk over their limits, the steps that named joints in
``StepInfo.limit_conflicts``, the hand's pose error at the end (``|log6|``, m and rad) and the
step's process time. pink's and mink's pulls over the same plate are in
:mod:`.collision_peers` and :mod:`.collision_mink`.

A ring (:func:`ring_grid`, a torus 46 cm across with a 34 cm hole, lying flat 18 cm under the
hand) shows what each way of keeping a mesh costs the task: the hand's position (a
:class:`~sjt_pin.tasks.PositionTask`) is sent 33 cm down through the hole along a line in 2 s
and held there 2 s, with the same limits; the final error is the position's (m). The hull
fills the hole in; the mesh as given leaves it open, but its closest points can jump; the
convex parts (:func:`sjt_pin.convex_parts`) leave it open and move their closest points
continuously.
"""

from __future__ import annotations

from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from ..limits import CollisionLimit, convex_parts
from ..limits.collision_geometry import coal_mesh
from ..robot import Robot
from ..solvers import make_solver
from ..tasks import PositionTask
from .collision import Checker, Scene, dash, failed_at, line_path, pose_error, rates, run_scene
from .collision_moving import franka_like

DT = 1e-3
PULL, HOLD = 2.0, 1.0  # s
RING_HOLD = 2.0  # s, the ring's run holds its end longer: the hand rests on its target


@dataclass
class MeshRow:
    convex: bool
    closest: float  # m, to the mesh, independent
    acceleration_ratio: float
    jerk_ratio: float
    conflicts: int | None  # steps naming joints in limit_conflicts (None: a peer has none)
    unreported: int | None  # steps above the acceleration or jerk limit (1.001x) that named none
    final_error: float  # m and rad
    us_per_step: float  # process time
    method: str = "SJT"
    failed_at: float = float("nan")  # s: when the solver failed and the run ended (nan: never)
    scene: str = "plate"  # "plate" (the pull) or "ring"
    parts: int = 0  # the obstacle given as this many convex parts (0: as one shape)
    kept: str = ""  # how the obstacle was kept: "convex hull", "mesh" or "N convex parts"


def plate_grid(size: float = 0.36, n: int = 24, height: float = 0.03, period: float = 0.08
               ) -> tuple[np.ndarray, np.ndarray]:
    """The vertices (n * n, 3; m) and triangles (2 (n - 1)^2, 3; vertex indices) of
    :func:`bumpy_plate`."""
    xs = np.linspace(-size / 2, size / 2, n)
    X, Y = np.meshgrid(xs, xs)
    Z = height * np.sin(2 * np.pi * X / period) * np.sin(2 * np.pi * Y / period)
    corners = np.arange(n * n).reshape(n, n)[:-1, :-1].ravel()
    triangles = np.concatenate([np.column_stack([corners, corners + 1, corners + n + 1]),
                                np.column_stack([corners, corners + n + 1, corners + n])])
    return np.column_stack([X.ravel(), Y.ravel(), Z.ravel()]), triangles


def bumpy_plate(size: float = 0.36, n: int = 24, height: float = 0.03,
                period: float = 0.08) -> coal.BVHModelOBBRSS:
    """A square plate of ``size`` (m) on an ``n`` x ``n`` grid whose height is ``height`` sin(2 pi
    x / period) sin(2 pi y / period): a non-convex triangle mesh, in its own frame."""
    return coal_mesh(*plate_grid(size, n, height, period))


def plate_scene(robot: Robot | None = None) -> Scene:
    """The pull over the plate (module docstring) as a :class:`.collision.Scene` (``robot``:
    Panda by default)."""
    robot = robot or Robot.from_example("panda")
    start = robot.fk(robot.q0)
    plate = (bumpy_plate(), pin.SE3(np.eye(3), start.translation + np.array([0.1, 0.0, -0.22])))
    end = pin.SE3(start.rotation, start.translation + np.array([0.0, 0.2, -0.17]))
    return Scene("Panda pulled over a plate of bumps", robot, robot.q0.copy(), [plate],
                 line_path(start, end, PULL), PULL, PULL + HOLD)


def ring_grid(major: float = 0.2, minor: float = 0.03, around: int = 24, section: int = 8
              ) -> tuple[np.ndarray, np.ndarray]:
    """The vertices (around * section, 3; m) and outward triangles (2 around section, 3) of a
    torus lying flat about the z axis, its tube's centre line a circle of radius ``major``, the
    tube's radius ``minor``: a closed, non-convex triangle mesh, in its own frame."""
    u = np.repeat(np.linspace(0.0, 2.0 * np.pi, around, endpoint=False), section)
    v = np.tile(np.linspace(0.0, 2.0 * np.pi, section, endpoint=False), around)
    rho = major + minor * np.cos(v)
    vertices = np.column_stack([rho * np.cos(u), rho * np.sin(u), minor * np.sin(v)])
    i, j = np.divmod(np.arange(around * section), section)
    a, b = i * section + j, ((i + 1) % around) * section + j
    c, d = ((i + 1) % around) * section + (j + 1) % section, i * section + (j + 1) % section
    return vertices, np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])


def ring_scene(robot: Robot | None = None) -> Scene:
    """The hand sent down through the ring (module docstring) as a :class:`.collision.Scene`
    (``robot``: Panda by default), the ring kept as its mesh."""
    robot = robot or Robot.from_example("panda")
    start = robot.fk(robot.q0)
    below = pin.SE3(np.eye(3), start.translation + np.array([0.0, 0.0, -0.18]))
    ring = (coal_mesh(*ring_grid()), below)
    end = pin.SE3(start.rotation, start.translation + np.array([0.0, 0.0, -0.33]))
    return Scene("Panda's hand through a ring", robot, robot.q0.copy(), [ring],
                 line_path(start, end, PULL), PULL, PULL + RING_HOLD)


def through_ring(kept: str, robot: Robot | None = None) -> MeshRow:
    """One run through the ring, the ring kept as ``kept``: ``"hull"`` (``convex=True``),
    ``"mesh"`` (``convex=False``) or ``"parts"`` (:func:`sjt_pin.convex_parts`, given as
    obstacles of their own)."""
    if kept not in ("hull", "mesh", "parts"):
        raise ValueError(f"kept must be 'hull', 'mesh' or 'parts', got {kept!r}")
    scene = ring_scene(robot)
    obstacles = scene.obstacles
    if kept == "parts":
        pose = obstacles[0][1]
        obstacles = [(part, pose) for part in convex_parts(ring_grid())]
    limit = CollisionLimit(scene.robot, obstacles, convex=kept != "mesh")
    accelerations, jerks = franka_like(scene.robot.nv)
    solver = make_solver("sjt", scene.robot, dt=DT, task=PositionTask(), limits=[limit],
                         acceleration_limits=accelerations, jerk_limits=jerks)
    reported: list[bool] = []
    qs, us = run_scene(scene, lambda q, pose, velocity: solver.step(q, pose.translation,
                                                                    velocity[:3]),
                       after=lambda: reported.append(bool(solver.last.limit_conflicts)))
    checker = Checker(scene.robot, scene.obstacles,
                      CollisionLimit(scene.robot, scene.obstacles, convex=False).pair_names)
    row = mesh_row(scene, kept != "mesh", qs, us, checker, np.array(reported), "SJT")
    row.scene = "ring"
    if kept == "parts":
        row.parts, row.kept = len(obstacles), f"{len(obstacles)} convex parts"
    row.final_error = float(np.linalg.norm(scene.robot.fk(qs[-1]).translation
                                           - scene.target(scene.duration)[0].translation))
    return row


def pull(convex: bool, robot: Robot | None = None) -> MeshRow:
    """One run of the pull over the plate (``robot``: Panda by default)."""
    scene = plate_scene(robot)
    limit = CollisionLimit(scene.robot, scene.obstacles, convex=convex)
    accelerations, jerks = franka_like(scene.robot.nv)
    solver = make_solver("sjt", scene.robot, dt=DT, limits=[limit],
                         acceleration_limits=accelerations, jerk_limits=jerks)
    reported: list[bool] = []
    qs, us = run_scene(scene, lambda q, pose, velocity: solver.step(q, pose, velocity),
                  after=lambda: reported.append(bool(solver.last.limit_conflicts)))
    return mesh_row(scene, convex, qs, us, Checker(scene.robot, scene.obstacles, limit.pair_names),
                    np.array(reported), "SJT")


def mesh_row(scene: Scene, convex: bool, qs: np.ndarray, us: float, checker: Checker,
             reported: np.ndarray | None, method: str) -> MeshRow:
    """The row of a pull whose configurations are ``qs`` (fewer than the scene's steps + 1 if
    the solver failed) and CPU time ``us`` per step: the distance to the mesh every 5th step
    (``checker``), the acceleration and jerk (:func:`.collision.rates`) over
    :func:`.collision_moving.franka_like`'s limits, the steps that ``reported`` a conflict (and
    those above a limit that did not; ``None``: the solver has no such report) and the hand's
    pose error at the end (m and rad)."""
    robot = scene.robot
    accelerations, jerks = franka_like(robot.nv)
    closest = min(checker.closest(q)[0] for q in qs[1::5]) if len(qs) > 1 else np.inf
    _, a, j = rates(robot.model, qs, DT)
    acceleration, jerk = np.abs(a) / accelerations, np.abs(j) / jerks
    conflicts = unreported = None
    if reported is not None:
        above = (np.max(acceleration, axis=1) > 1.001) | (np.max(jerk, axis=1) > 1.001)
        conflicts, unreported = int(reported.sum()), int(np.sum(above & ~reported))
    end, _ = scene.target(scene.duration)
    return MeshRow(convex, float(closest), float(np.max(acceleration, initial=0.0)),
                   float(np.max(jerk, initial=0.0)), conflicts, unreported,
                   pose_error(robot, qs[-1], end), us, method,
                   failed_at(qs, int(round(scene.duration / DT)), DT),
                   kept="convex hull" if convex else "mesh")


def mesh_table(rows: list[MeshRow]) -> str:
    """The rows as a markdown table (distances in mm; "failed at" in s)."""
    head = ("| method | obstacle kept as | closest mm (mesh) | accel. / limit | jerk / limit "
            "| steps with conflicts | unreported | final error | failed at | us/step |\n"
            "|---|---|---|---|---|---|---|---|---|---|\n")
    return head + "".join(
        f"| {r.method} | {r.kept} | {1e3 * r.closest:.2f} "
        f"| {r.acceleration_ratio:.2f} | {r.jerk_ratio:.2f} | {dash(r.conflicts, 'd')} "
        f"| {dash(r.unreported, 'd')} | {r.final_error:.3f} | "
        f"{dash(r.failed_at, '.3f')} | {r.us_per_step:.0f} |\n"
        for r in rows)
