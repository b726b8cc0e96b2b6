"""pink on ``sjt-pin bench collision``'s scenes: the three still scenes of :mod:`.collision`, the
ball driven at the hand of :mod:`.collision_moving` and the plate of bumps of
:mod:`.collision_mesh`, each measured as the SJT rows beside it are.

pink (``pin-pink``, its QP solved with qpsolvers' daqp) tracks the hand's target with a
``FrameTask`` and a small ``PostureTask`` within its ``ConfigurationLimit`` and
``VelocityLimit`` (and, where the SJT rows have Franka-like limits, its ``AccelerationLimit``
with the same accelerations; pink has no jerk limit). It keeps off collisions with its
``SelfCollisionBarrier`` on the limit's own geometry model (the robot's hulls, or its meshes
as given with ``convex=False``, and the obstacles on the world joint: every pair the limit
checks is a barrier row), with ``d_min`` the limit's margin and the limit's damper: pink's
barrier lets ``d - d_min`` shrink by ``gain dt`` per step (``gain`` in 1/s), so ``gain`` is
``CollisionLimit.gain / dt`` (0.5 per step).

pink cannot be told an obstacle's velocity: the ball's pose is set in the geometry model
before each step (``Configuration.update`` then computes the distances), and the barrier is
made anew each step, since a ``SelfCollisionBarrier`` caches its distances and Jacobian keyed
on ``q`` alone (kept across steps, it would not see the ball come while the arm stands still).
A step whose QP has no solution (``NoSolutionFound``) ends the run and the row says when
(``failed_at``, s). The time per step is that of the ball's pose, ``Configuration.update``,
``solve_ik`` and ``integrate`` (process time). Rows only where pink and qpsolvers are installed.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import pinocchio as pin

from ..limits import CollisionLimit
from ..robot import Robot
from .collision import DT, Checker, CollisionRow, Scene, failed_at, run_scene, run_steps, scene_row
from .collision_mesh import MeshRow, mesh_row, plate_scene
from .collision_moving import MARGIN, TRAVEL, MovingRow, ball, franka_like, moving_row, sweep


def available() -> bool:
    """Whether pink and a QP solver of qpsolvers are installed."""
    try:
        import pink  # noqa: F401
        import qpsolvers
    except ImportError:
        return False
    return bool(qpsolvers.available_solvers)


class PinkArm:
    """pink's ``solve_ik`` on ``robot`` at period ``dt`` (s) from ``q0``, with the barrier of
    ``limit`` (a copy of its geometry model, its margin and gain; ``None``: no barrier) and
    ``accelerations`` (rad/s^2, ``None``: no acceleration limit); module docstring."""

    def __init__(self, robot: Robot, q0: np.ndarray, dt: float,
                 limit: CollisionLimit | None = None,
                 accelerations: np.ndarray | None = None):
        import pink
        import qpsolvers
        from pink.limits import AccelerationLimit
        from pink.tasks import FrameTask, PostureTask

        self.dt = dt
        self.qp = ("daqp" if "daqp" in qpsolvers.available_solvers
                   else qpsolvers.available_solvers[0])
        model = robot.model
        self.geometry = None
        if limit is not None:
            self.geometry = limit.geometry.copy()  # the same hulls, pairs and obstacles
            geometry_data = self.geometry.createData()
            for request in geometry_data.distanceRequests:
                request.enable_signed_distance = True
            self.margin, self.gain = limit.margin, limit.gain / dt
            self.configuration = pink.Configuration(model, model.createData(), q0,
                                                    collision_model=self.geometry,
                                                    collision_data=geometry_data)
        else:
            self.configuration = pink.Configuration(model, model.createData(), q0)
        self.acceleration = None
        self.limits = None  # (pink's default: its configuration and velocity limits)
        if accelerations is not None:
            self.acceleration = AccelerationLimit(model, np.asarray(accelerations, float))
            self.limits = [model.configuration_limit, model.velocity_limit, self.acceleration]
        self.task = FrameTask(robot.ee_frame, position_cost=1.0, orientation_cost=1.0)
        self.posture = PostureTask(cost=1e-3)
        self.posture.set_target(q0)

    def move(self, i: int, pose: pin.SE3) -> None:
        """Put obstacle ``i`` at ``pose`` in pink's geometry model (no velocity: pink has no
        place for it)."""
        assert self.geometry is not None
        self.geometry.geometryObjects[self.geometry.getGeometryId(f"obstacle_{i}")].placement = (
            pose)

    def step(self, q: np.ndarray, target: pin.SE3) -> np.ndarray | None:
        """One step towards the hand's ``target``: the next configuration, or ``None`` if
        pink's QP has no solution."""
        import pink
        from pink.barriers import SelfCollisionBarrier
        from pink.exceptions import NoSolutionFound

        self.configuration.update(q)
        self.task.set_target(target)
        barriers = [] if self.geometry is None else [SelfCollisionBarrier(
            len(self.geometry.collisionPairs), gain=self.gain, d_min=self.margin)]
        try:
            v = pink.solve_ik(self.configuration, [self.task, self.posture], self.dt,
                              solver=self.qp, barriers=barriers, limits=self.limits,
                              safety_break=False)
        except NoSolutionFound:
            return None
        if self.acceleration is not None:
            self.acceleration.set_last_integration(v, self.dt)
        return self.configuration.integrate(v, self.dt)


def pink_scene(scene: Scene, limit: CollisionLimit, barrier: bool, checker: Checker
               ) -> CollisionRow | None:
    """pink on a still scene of :mod:`.collision`, with the barrier of ``limit`` or without
    any; ``None`` without pink. A failed run's row has ``extra["failed_at"]`` (s)."""
    if not available():
        return None
    arm = PinkArm(scene.robot, scene.q0, DT, limit if barrier else None)
    qs, us = run_scene(scene, lambda q, pose, velocity: arm.step(q, pose))
    row = scene_row(scene, "pink", barrier, qs, us, checker)
    failed = failed_at(qs, int(round(scene.duration / DT)), DT)
    if not np.isnan(failed):
        row.extra["failed_at"] = failed
    return row


def pink_drive(robot: Robot, speed: float, dt: float, smooth: bool = False,
               travel: float = TRAVEL) -> MovingRow:
    """pink beside the ball of :func:`.collision_moving.drive` (``speed`` in m/s, ``dt`` in s,
    ``travel`` in m), with its acceleration limit at Franka's accelerations if ``smooth``."""
    driven = ball(robot, speed, dt, travel)
    limit = CollisionLimit(robot, driven.obstacles, margin=MARGIN)
    driven.checker = Checker(robot, driven.obstacles, limit.pair_names)
    arm = PinkArm(robot, robot.q0, dt, limit, franka_like(robot.nv)[0] if smooth else None)

    def step(q, pose, velocity):
        arm.move(0, pose)
        return arm.step(q, driven.hand)

    qs, us = run_steps(robot.q0, driven.path, step)
    return moving_row(robot, driven, dt, smooth, False, qs, us, None, "pink")


def pink_moving(robots: Sequence[str] = ("panda", "ur5"),
                progress: Callable[[MovingRow], object] | None = None) -> list[MovingRow]:
    """pink on every robot at 0.5 and 1 m/s: at 1 kHz and 100 Hz with speed limits, and at
    1 kHz with its acceleration limit (:func:`pink_drive`); empty without pink."""
    if not available():
        return []
    return sweep(robots, ((1e-3, False), (1e-2, False), (1e-3, True)), pink_drive, progress)


def pink_pull(convex: bool, scene: Scene | None = None) -> MeshRow:
    """pink on the pull over the plate of :func:`.collision_mesh.pull` (``scene``: that of
    :func:`.collision_mesh.plate_scene` by default), the plate and the robot kept as hulls
    (``convex``) or as given, with its acceleration limit at Franka's accelerations."""
    scene = scene or plate_scene()
    limit = CollisionLimit(scene.robot, scene.obstacles, convex=convex)
    arm = PinkArm(scene.robot, scene.q0, DT, limit, franka_like(scene.robot.nv)[0])
    qs, us = run_scene(scene, lambda q, pose, velocity: arm.step(q, pose))
    return mesh_row(scene, convex, qs, us, Checker(scene.robot, scene.obstacles,
                                                   limit.pair_names), None, "pink")


def pink_mesh(progress: Callable[[MeshRow], object] | None = None) -> list[MeshRow]:
    """:func:`pink_pull` with the plate as its hull and as given; empty without pink."""
    if not available():
        return []
    rows = []
    for convex in (True, False):
        rows.append(pink_pull(convex))
        if progress is not None:
            progress(rows[-1])
    return rows

