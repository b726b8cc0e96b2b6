"""``sjt-pin bench collision``: collision avoidance on three scenes, with and without the
limit, for SJT, DLS and pink.

- **Panda passes a ball** (:func:`scenes`): the hand follows a 40 cm line in 2 s that an 8 cm
  sphere lies beside (the free arm drives its links into it), then holds the end, reachable
  without touching, for 2 s. Self-collision on.
- **Panda beside its base**: the hand is sent in 1.5 s to a pose beside and behind the robot's
  own base (on the way the free arm drives its hand through link 2); the pose itself is
  reachable without touching. Self-collision on.
- **UR5 under a table**: a 4 cm table top 20 cm under the hand; the target goes down through
  it in 1.5 s to 3 cm under it and stays there: the arm must stop above it, at rest.

Each run reports the least distance of any checked pair, **measured independently**: coal on
a geometry model of its own, built from the robot's collision meshes (not the limit's convex
hulls, not the limit's numbers; each pair's hull distance, a lower bound, picks the pairs whose
mesh distance is computed), the task error 2 s after the target stops, the RMS joint speed over
the last second, and the CPU time per step (process time, so other processes do not count;
the least of five runs).
pink runs its ``SelfCollisionBarrier`` on a geometry model with the obstacles attached to the
world joint (its way to handle obstacles: every pair of its collision model is a barrier row),
on the same convex hulls as the limit, with a ``FrameTask`` and a small ``PostureTask``, and
the limit's damper (:mod:`.collision_peers`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import coal
import numpy as np
import pinocchio as pin

from ..limits.collision import CollisionLimit
from ..limits.collision_geometry import collision_model_of, to_hulls
from ..robot import Robot
from ..solvers import make_solver
from ..trajectories import PoseInterpolation

DT = 1e-3
MARGIN = 0.01
#: runs of each line whose least CPU time per step is reported (as timeit's best of
#: several), the runs without and with the limit in turn: another process's burst slows one
#: run by up to 3x on a shared machine, and the ratio of two single runs inherits both runs'
#: noise; the runs are deterministic (the same configurations each time), so the first
#: one's are checked
TIMING_RUNS = 5
#: the hull distance (m) under which a pair's mesh distance is computed in the check
CHECK_BELOW = 0.03
UR5_START = np.array([0.0, -1.2, 1.5, -1.9, -1.57, 0.0])


@dataclass
class Scene:
    """A robot, its obstacles, a path of targets (pose and velocity at time t) and how long
    the run lasts (s); ``stop`` is when the target stops moving."""

    name: str
    robot: Robot
    q0: np.ndarray
    obstacles: list
    target: Callable[[float], tuple[pin.SE3, np.ndarray]]
    stop: float
    duration: float
    self_collision: bool = True


@dataclass
class CollisionRow:
    scene: str
    method: str
    limit: bool
    min_distance: float  # m, any checked pair, meshes, independent
    pair: str  # the closest pair
    final_error: float  # |e| 2 s after the target stops (m and rad)
    rest: float  # RMS joint speed over the last second, rad/s
    us_per_step: float  # CPU time of one step, us
    floor_us: float = float("nan")  # plain step + coal's queries of the active pairs, us
    rows_us: float = float("nan")  # the limit's rows() alone (broad phase, coal, rows), us
    extra: dict = field(default_factory=dict)


def line_path(start: pin.SE3, end: pin.SE3, duration: float):
    path = PoseInterpolation(start, end, duration=duration)

    def target(t: float):
        pose, velocity = path.sample(min(t, duration))
        return pose, (np.zeros(6) if t >= duration else velocity.vector)

    return target


def scenes() -> list[Scene]:
    """The three scenes of the module docstring."""
    panda = Robot.from_example("panda")
    q0 = panda.q0.copy()
    start = panda.fk(q0)
    end = pin.SE3(start.rotation, start.translation + [0.0, 0.4, 0.0])
    ball = (coal.Sphere(0.04), pin.SE3(np.eye(3), start.translation + [0.0, 0.2, -0.07]))
    side = pin.SE3(start.rotation, np.array([-0.1, 0.25, 0.35]))  # behind, left of link 1
    ur5 = Robot.from_example("ur5")
    top = ur5.fk(UR5_START)
    table = (coal.Box(0.6, 0.8, 0.04), pin.SE3(np.eye(3), np.array([top.translation[0],
                                                                     top.translation[1],
                                                                     top.translation[2] - 0.2])))
    below = pin.SE3(top.rotation, top.translation - [0.0, 0.0, 0.25])
    return [
        Scene("Panda passes a ball", panda, q0, [ball], line_path(start, end, 2.0), 2.0, 4.0),
        Scene("Panda beside its base", panda, q0, [], line_path(start, side, 1.5), 1.5, 3.5),
        Scene("UR5 under a table", ur5, UR5_START.copy(), [table], line_path(top, below, 1.5), 1.5,
              3.5),
    ]


def rates(model: pin.Model, qs, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The joint velocities, accelerations and jerks (N, nv) of the configurations ``qs``
    (N + 1, nq) a solver returned at period ``dt``: finite differences on the model's tangent
    space (``pin.difference``), from rest before the first step."""
    v = np.array([pin.difference(model, a, b) for a, b in zip(qs[:-1], qs[1:], strict=True)]
                 ).reshape(-1, model.nv) / dt  # (no step: (0, nv))
    a = np.diff(np.vstack([np.zeros((1, model.nv)), v]), axis=0) / dt
    j = np.diff(np.vstack([np.zeros((1, model.nv)), a]), axis=0) / dt
    return v, a, j


class Checker:
    """The least distance of the pairs a limit checks, computed independently (module
    docstring): meshes where the robot has them, obstacles as given."""

    def __init__(self, robot: Robot, obstacles, pair_names):
        self.model = robot.model
        self.data = robot.model.createData()
        self.mesh = collision_model_of(robot)  # (a URDF file's robot loads it here)
        for i, (shape, pose) in enumerate(obstacles):
            self.mesh.addGeometryObject(pin.GeometryObject(f"obstacle_{i}", 0, 0, pose, shape))
        names = [g.name for g in self.mesh.geometryObjects]
        self.mesh.removeAllCollisionPairs()
        for a, b in pair_names:
            self.mesh.addCollisionPair(pin.CollisionPair(names.index(a), names.index(b)))
        self.hull = self.mesh.copy()
        to_hulls(self.hull)
        self.mesh_data, self.hull_data = self.mesh.createData(), self.hull.createData()
        for data in (self.mesh_data, self.hull_data):
            for req in data.distanceRequests:
                req.enable_signed_distance = True
        self.names = [(names[p.first], names[p.second]) for p in self.mesh.collisionPairs]
        self._obstacles = [names.index(f"obstacle_{i}") for i in range(len(obstacles))]

    def move(self, i: int, pose: pin.SE3) -> None:
        """Move obstacle ``i`` to ``pose`` (a moving obstacle's scene)."""
        for geometry in (self.mesh, self.hull):
            geometry.geometryObjects[self._obstacles[i]].placement = pose

    def closest(self, q: np.ndarray) -> tuple[float, str]:
        """(distance in m, pair) of the closest pair at ``q``."""
        pin.updateGeometryPlacements(self.model, self.data, self.hull, self.hull_data, q)
        pin.updateGeometryPlacements(self.model, self.data, self.mesh, self.mesh_data)
        best, pair = np.inf, ""
        for k in range(len(self.names)):
            d = pin.computeDistance(self.hull, self.hull_data, k).min_distance
            if d < CHECK_BELOW:  # the hull is a lower bound: only then the mesh can be close
                d = pin.computeDistance(self.mesh, self.mesh_data, k).min_distance
            if d < best:
                best, pair = d, "/".join(self.names[k])
        return float(best), pair


def dash(x: float | int | None, spec: str = ".2f") -> str:
    """``x`` formatted for a table, or ``-`` where there is no value (``None`` or NaN)."""
    return "-" if x is None or x != x else format(x, spec)


def pose_error(robot: Robot, q: np.ndarray, target: pin.SE3) -> float:
    return float(np.linalg.norm(pin.log6(robot.fk(q).actInv(target)).vector))


def run_steps(q0: np.ndarray, inputs: Sequence[tuple],
              step: Callable[..., np.ndarray | None],
              after: Callable[[], object] | None = None) -> tuple[np.ndarray, float]:
    """Run ``step(q, *item) -> q`` for each item of ``inputs`` from ``q0``: the configurations
    (N + 1, nq) and the CPU time per step (us, process time). ``after()``, if given, is
    called after each step and left out of the time (a solver's report, say). A step that
    returns ``None`` (its solver failed) ends the run there: the configurations then stop at
    the last one it returned, and the time is per step tried."""
    q = q0.copy()
    qs = [q]
    clock = time.process_time
    start = clock()
    for item in inputs:
        stepped = step(q, *item)
        if stepped is None:
            break
        q = stepped
        qs.append(q)
        if after is not None:
            pause = clock()
            after()
            start += clock() - pause
    tried = min(len(qs), len(inputs))
    return np.array(qs), (clock() - start) / max(tried, 1) * 1e6


def failed_at(qs: np.ndarray, steps: int, dt: float) -> float:
    """When (s) a run of :func:`run_steps` over ``steps`` inputs ended because its solver
    failed (its configurations ``qs`` stop short), or nan if it ran them all."""
    made = len(qs) - 1
    return round(made * dt, 9) if made < steps else float("nan")


def run_scene(scene: Scene, step, after=None) -> tuple[np.ndarray, float]:
    """Run ``step(q, pose, velocity) -> q`` over the scene (:func:`run_steps`)."""
    return run_steps(scene.q0, [scene.target(k * DT)
                                for k in range(int(round(scene.duration / DT)))], step, after)


def scene_row(scene: Scene, method: str, limit: bool, qs: np.ndarray, us: float, checker: Checker,
         ) -> CollisionRow:
    closest = [checker.closest(q) for q in qs]
    worst = min(range(len(closest)), key=lambda i: closest[i][0])
    settle = min(len(qs) - 1, int(round((scene.stop + 2.0) / DT)))
    end_pose, _ = scene.target(scene.duration)
    speed = np.diff(qs[-int(1.0 / DT) - 1:], axis=0) / DT
    return CollisionRow(scene.name, method, limit, closest[worst][0], closest[worst][1],
                        pose_error(scene.robot, qs[settle], end_pose),
                        float(np.sqrt(np.mean(speed ** 2))), us)


def _floor(scene: Scene, limit: CollisionLimit, qs: np.ndarray, plain_us: float
           ) -> tuple[float, float]:
    """The plain step's time plus coal's distance queries of the pairs the limit had within
    ``influence`` at each configuration of the run, and the time of the limit's ``rows()``
    alone at the same configurations (us per step)."""
    from ..kinematics import Kinematics
    from ..limits.base import Motion

    kinematics = Kinematics(scene.robot.model)
    motion = Motion(scene.q0, np.zeros(scene.robot.nv), np.zeros(scene.robot.nv), DT)
    active = []
    clock = time.process_time
    rows_time = 0.0
    for q in qs[:-1]:
        kinematics.update(q)
        start = clock()
        limit.rows(kinematics, motion)
        rows_time += clock() - start
        active.append(list(limit.within))
    geometry, data = limit.geometry, limit.geometry_data
    model, pin_data = scene.robot.model, kinematics.data
    best = np.inf
    for _ in range(TIMING_RUNS):
        start = clock()
        for q, pairs in zip(qs[:-1], active, strict=True):
            if pairs:
                pin.updateGeometryPlacements(model, pin_data, geometry, data, q)
                for k in pairs:
                    pin.computeDistance(geometry, data, k)
        best = min(best, clock() - start)
    return (plain_us + best / len(active) * 1e6, rows_time / len(active) * 1e6)


#: a peer's row on a scene: ``peer(scene, limit, barrier, checker)`` with its barrier on
#: ``limit``'s geometry (``barrier``) or without; ``None`` where the peer is not installed
#: (:func:`.collision_peers.pink_scene`)
Peer = Callable[[Scene, CollisionLimit, bool, Checker], CollisionRow | None]


def collision(methods=("sjt", "dls"), peer: Peer | None = None,
              progress=None) -> list[CollisionRow]:
    """Every scene (module docstring), every method with and without the limit, and
    ``peer``'s rows without and with its barrier; the CPU time per step of SJT and DLS is the
    least of :data:`TIMING_RUNS` runs, with and without the limit alike, and so is the coal
    part of the floor."""
    rows = []
    for scene in scenes():
        limit = CollisionLimit(scene.robot, scene.obstacles, self_collision=scene.self_collision,
                               margin=MARGIN)
        checker = Checker(scene.robot, scene.obstacles, limit.pair_names)
        for method in methods:
            runs: dict[bool, list] = {False: [], True: []}
            for _ in range(TIMING_RUNS):  # (without and with in turn: both see the same load)
                for with_limit in (False, True):
                    fence = CollisionLimit(scene.robot, scene.obstacles,
                                           self_collision=scene.self_collision, margin=MARGIN)
                    solver = make_solver(method, scene.robot, dt=DT,
                                         limits=[fence] if with_limit else ())
                    runs[with_limit].append(
                        (*run_scene(scene, lambda q, pose, v, s=solver: s.step(q, pose, v)), fence))
            plain_us = min(us for _, us, _ in runs[False])
            for with_limit in (False, True):
                qs, _, fence = runs[with_limit][0]
                us = min(us for _, us, _ in runs[with_limit])
                row = scene_row(scene, method.upper(), with_limit, qs, us, checker)
                if with_limit:
                    row.floor_us, row.rows_us = _floor(scene, fence, qs, plain_us)
                rows.append(row)
                if progress:
                    progress(row)
        if peer is not None:
            for with_barrier in (False, True):
                row = peer(scene, limit, with_barrier, checker)
                if row is None:
                    break
                rows.append(row)
                if progress:
                    progress(row)
    return rows


def collision_table(rows: list[CollisionRow]) -> str:
    out = ["| scene | method | limit | min distance [mm] | closest pair | error 2 s after the "
           "stop | RMS speed, last 1 s [rad/s] | CPU us/step | of which rows() | "
           "with / (plain + coal) |",
           "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        ratio = r.us_per_step / r.floor_us if np.isfinite(r.floor_us) else float("nan")
        out.append(f"| {r.scene} | {r.method} | {'yes' if r.limit else 'no'} | "
                   f"{1e3 * r.min_distance:.1f} | {r.pair} | {r.final_error:.1e} | "
                   f"{r.rest:.1e} | {r.us_per_step:.0f} | "
                   f"{'' if np.isnan(r.rows_us) else f'{r.rows_us:.0f}'} | "
                   f"{'' if np.isnan(ratio) else f'{ratio:.1f}'} |")
    return "\n".join(out)


def idle(steps: int = 3000) -> tuple[float, float]:
    """CPU time per step (us) of SJT on Panda's 40 cm line without a limit, and with a
    CollisionLimit (self-collision on, one ball 3 m away) whose pairs all stay beyond
    ``influence``: the limit's cost when nothing is near (the broad phase alone); the least
    of :data:`TIMING_RUNS` runs of each, in turn."""
    scene = scenes()[0]
    far = [(coal.Sphere(0.04), pin.SE3(np.eye(3), np.array([3.0, 0.0, 0.0])))]
    scene = Scene("idle", scene.robot, scene.q0, far, scene.target, 2.0, steps * DT)
    solvers = [make_solver("sjt", scene.robot, dt=DT, limits=limits)
               for limits in ((), (CollisionLimit(scene.robot, far, self_collision=True,
                                                  margin=MARGIN),))]
    best = [np.inf, np.inf]
    for _ in range(TIMING_RUNS):  # (without and with in turn, as collision())
        for i, solver in enumerate(solvers):
            _, us = run_scene(scene, lambda q, pose, v, s=solver: s.step(q, pose, v))
            best[i] = min(best[i], us)
    return best[0], best[1]


@dataclass
class Crowded:
    """:func:`crowded`'s result: pairs checked, CPU time per step (us) without and with the
    limit (median and 99th percentile of single steps), and the least distance (m, checked
    independently)."""

    pairs: int
    plain_us: float
    median_us: float
    p99_us: float
    min_distance: float


def crowd(robot: Robot, q0: np.ndarray, count: int = 20, clearance: float = 0.06,
          seed: int = 0) -> list:
    """``count`` seeded obstacles (spheres, boxes, capsules, random turns) in a 1.6 x 1.6 x
    1.2 m box around the robot's base, each at least ``clearance`` (m) from the robot at
    ``q0``."""
    rng = np.random.default_rng(seed)
    obstacles: list = []
    while len(obstacles) < count:
        centre = rng.uniform([-0.8, -0.8, 0.0], [0.8, 0.8, 1.2])
        shape = [coal.Sphere(rng.uniform(0.03, 0.08)), coal.Box(*rng.uniform(0.04, 0.15, 3)),
                 coal.Capsule(0.04, 0.15)][int(rng.integers(3))]
        candidate = (shape, pin.SE3(pin.exp3(rng.normal(size=3)), centre))
        probe = CollisionLimit(robot, [candidate], margin=0.0)
        if min(d.distance for d in probe.distances(q0)) > clearance:
            obstacles.append(candidate)
    return obstacles


def crowded(steps: int = 3000) -> Crowded:
    """SJT on the first scene (Panda's hand passes a ball on a 40 cm line) with 19 more
    obstacles of :func:`crowd`, self-collision on: the limit's cost with many pairs, most of
    which the broad phase leaves out (three runs without and with the limit in turn: the
    least median of each, the 99th percentile of that run with the limit)."""
    scene = scenes()[0]
    obstacles = scene.obstacles + crowd(scene.robot, scene.q0, count=19)
    scene = Scene("crowded", scene.robot, scene.q0, obstacles, scene.target, 2.0, steps * DT)
    targets = [scene.target(k * DT) for k in range(steps)]
    plain, runs, qs = np.inf, [], []
    for _ in range(3):  # (without and with in turn; the run with the least median is kept)
        for with_limit in (False, True):
            limit = CollisionLimit(scene.robot, obstacles, self_collision=True, margin=MARGIN)
            solver = make_solver("sjt", scene.robot, dt=DT, limits=[limit] if with_limit else [])
            q, each, path = scene.q0.copy(), [], []
            for pose, velocity in targets:
                start = time.process_time_ns()
                q = solver.step(q, pose, velocity)
                each.append((time.process_time_ns() - start) / 1e3)
                path.append(q)
            if with_limit:
                runs.append(each)
                qs = qs or path
            else:
                plain = min(plain, float(np.median(each)))
    each = min(runs, key=np.median)
    checker = Checker(scene.robot, obstacles, limit.pair_names)
    closest = min(checker.closest(q)[0] for q in qs[::10])
    return Crowded(len(limit.pair_names), plain, float(np.median(each)),
                   float(np.percentile(each, 99)), closest)

