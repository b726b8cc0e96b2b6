"""mink on ``sjt-pin bench collision``'s ball driven at the hand (:mod:`.collision_moving`) and
plate of bumps (:mod:`.collision_mesh`), measured as the SJT rows beside them are.

mink (``pip install mink``) solves on a MuJoCo model. MuJoCo compiles the robot's own URDF (the
one example-robot-data ships) once its ``package://`` mesh paths are written as file paths
and its visual meshes left out (MuJoCo reads no ``.dae``); the obstacles are added with
``MjSpec``: the ball as a mocap body whose position is set before each step (mink, as pink,
cannot be told an obstacle's velocity), the plate as a mesh geom, which MuJoCo collides as its
convex hull (so mink has no run with the plate as given). mink tracks the hand's target with a
``FrameTask`` and a small ``PostureTask`` within its ``ConfigurationLimit``, a
``VelocityLimit`` at the robot's speed limits and a ``CollisionAvoidanceLimit`` between every
robot geom and the obstacle, with the limit's margin (``minimum_distance_from_collisions``),
influence (``collision_detection_distance``) and damper: ``CollisionLimit`` lets a step close
``gain`` (0.5) of ``d - margin``; mink bounds the step's displacement by its ``gain (d -
margin) / dt`` (its QP's variable is the displacement), so its gain is 0.5 dt (with the 0.5
of its own (0, 1] range, a step at 1 kHz could close 500 times the gap), its QP solved with
daqp. mink has no acceleration or jerk limit: its moving runs are those
with speed limits alone; the pull's ratios are to Franka's limits, as the SJT rows'. MuJoCo
keeps Panda's second finger as a joint of its own (Pinocchio's mimics the first): it is set
to the first's value and held by the posture; configurations are mapped to Pinocchio's by
joint name. Rows only where mink is installed.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from ..limits import CollisionLimit
from ..robot import Robot
from .collision import DT, Checker, Scene, run_scene, run_steps
from .collision_mesh import MeshRow, mesh_row, plate_grid, plate_scene
from .collision_moving import MARGIN, TRAVEL, Ball, MovingRow, ball, moving_row, sweep

if TYPE_CHECKING:
    import mujoco

INFLUENCE = 0.05  # m, CollisionLimit's default


def available() -> bool:
    """Whether mink (and MuJoCo) are installed."""
    try:
        import mink  # noqa: F401
        import mujoco  # noqa: F401
    except ImportError:
        return False
    return True


def mujoco_spec(robot: Robot) -> mujoco.MjSpec:
    """A ``mujoco.MjSpec`` of ``robot``'s URDF file, its ``package://`` paths resolved in its
    ``package_dirs`` and its visual meshes left out."""
    import mujoco

    if robot.urdf is None:
        raise ValueError(f"{robot.name}: no URDF file to compile")

    def resolve(match: re.Match) -> str:
        for folder in robot.package_dirs:
            if (Path(folder) / match.group(1)).exists():
                return f"{folder}/{match.group(1)}"
        return match.group(0)

    text = re.sub(r"package://([^\"']+)", resolve, Path(robot.urdf).read_text())
    text = re.sub(r"(<robot[^>]*>)", r'\1<mujoco><compiler discardvisual="true" '
                  r'strippath="false" fusestatic="false"/></mujoco>', text, count=1)
    return mujoco.MjSpec.from_string(text)


class MinkArm:
    """mink's ``solve_ik`` on ``robot`` at period ``dt`` (s), compiled with its obstacle
    ``obstacle`` (a function that adds it to the ``MjSpec`` and returns its geom's name); the
    configurations in and out are Pinocchio's (module docstring)."""

    def __init__(self, robot: Robot, dt: float, obstacle: Callable[[mujoco.MjSpec], str],
                 gain: float = 0.5):
        # (``gain``: the share of d - margin a step may close, CollisionLimit's; mink's
        # limit bounds the displacement J dq by its gain (d - margin) / dt, so its gain is
        # ``gain * dt``)
        import mink

        spec = mujoco_spec(robot)
        geom = obstacle(spec)
        self.model = model = spec.compile()
        self.robot, self.dt = robot, dt
        # Pinocchio's q index -> MuJoCo's qpos index (every joint is 1-dof here)
        joints = [(robot.model.names[j], robot.model.joints[j])
                  for j in range(1, robot.model.njoints) if robot.model.joints[j].nq > 0]
        self.address = np.zeros(robot.nq, dtype=int)
        speeds = {}
        for name, joint in joints:
            self.address[joint.idx_q] = model.joint(name).qposadr[0]
            speeds[name] = robot.velocity_limits[joint.idx_v]
        mimics = list(getattr(robot, "mimic_joints", ()))
        self.mimics = [(model.joint(m.joint).qposadr[0], model.joint(m.mimicked).qposadr[0],
                        m.multiplier, m.offset) for m in mimics]
        speeds.update({m.joint: speeds[m.mimicked] for m in mimics})
        self.configuration = mink.Configuration(model)
        q0 = self.to_mujoco(robot.q0)
        self.configuration.update(q0)
        frame = robot.model.frames[robot.frame_id(robot.ee_frame)].name
        self.task = mink.FrameTask(frame, "body", position_cost=1.0, orientation_cost=1.0)
        self.posture = mink.PostureTask(model, cost=1e-3)
        self.posture.set_target(q0)
        obstacle_body = model.geom(geom).bodyid[0]
        robot_geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] != obstacle_body]
        self.limits = [mink.ConfigurationLimit(model), mink.VelocityLimit(model, speeds),
                       mink.CollisionAvoidanceLimit(
                           model, [(robot_geoms, [geom])], gain=gain * dt,
                           minimum_distance_from_collisions=MARGIN,
                           collision_detection_distance=INFLUENCE)]

    def to_mujoco(self, q: np.ndarray) -> np.ndarray:
        """Pinocchio's ``q`` as MuJoCo's ``qpos`` (mimic joints set from theirs)."""
        qpos = np.zeros(self.model.nq)
        qpos[self.address] = q
        for adr, mimicked, multiplier, offset in self.mimics:
            qpos[adr] = multiplier * qpos[mimicked] + offset
        return qpos

    def step(self, q: np.ndarray, target: pin.SE3, ball_at: np.ndarray | None = None
             ) -> np.ndarray | None:
        """One step towards the hand's ``target`` (the ball's mocap body at ``ball_at``, m):
        the next configuration (Pinocchio's), or ``None`` if mink's QP has no solution."""
        import mink

        if ball_at is not None:
            self.configuration.data.mocap_pos[0] = ball_at
        self.configuration.update(self.to_mujoco(q))
        self.task.set_target(mink.SE3.from_matrix(target.homogeneous))
        try:
            v = mink.solve_ik(self.configuration, [self.task, self.posture], self.dt, "daqp",
                              limits=self.limits)
        except mink.NoSolutionFound:
            return None
        self.configuration.integrate_inplace(v, self.dt)
        return self.configuration.q[self.address].copy()


def add_ball(spec: mujoco.MjSpec, driven: Ball) -> str:
    """Add the ball of ``driven`` to ``spec`` as a mocap body at its first position; its geom's
    name."""
    import mujoco

    body = spec.worldbody.add_body(name="ball", mocap=True, pos=driven.path[0][0].translation)
    body.add_geom(name="ball", type=mujoco.mjtGeom.mjGEOM_SPHERE,
                  size=[driven.shape.radius, 0.0, 0.0])
    return "ball"


def mink_drive(robot: Robot, speed: float, dt: float, travel: float = TRAVEL) -> MovingRow:
    """mink beside the ball of :func:`.collision_moving.drive` (``speed`` in m/s, ``dt`` in s,
    ``travel`` in m), with speed limits alone."""
    driven = ball(robot, speed, dt, travel)
    arm = MinkArm(robot, dt, lambda spec: add_ball(spec, driven))
    limit = CollisionLimit(robot, driven.obstacles, margin=MARGIN)
    driven.checker = Checker(robot, driven.obstacles, limit.pair_names)
    qs, us = run_steps(robot.q0, driven.path,
                       lambda q, pose, velocity: arm.step(q, driven.hand, pose.translation))
    return moving_row(robot, driven, dt, False, False, qs, us, None, "mink")


def mink_moving(robots: Sequence[str] = ("panda", "ur5"),
                progress: Callable[[MovingRow], object] | None = None) -> list[MovingRow]:
    """mink on every robot at 0.5 and 1 m/s, at 1 kHz and 100 Hz (:func:`mink_drive`); empty
    without mink."""
    if not available():
        return []
    return sweep(robots, ((1e-3,), (1e-2,)), mink_drive, progress)


def mink_pull(scene: Scene | None = None) -> MeshRow:
    """mink on the pull over the plate of :func:`.collision_mesh.pull` (``scene``: that of
    :func:`.collision_mesh.plate_scene` by default), the plate collided as its hull."""
    import mujoco

    scene = scene or plate_scene()
    _, pose = scene.obstacles[0]
    vertices, triangles = plate_grid()

    def add_plate(spec: mujoco.MjSpec) -> str:
        spec.add_mesh(name="plate", uservert=vertices.ravel().tolist(),
                      userface=triangles.ravel().tolist())
        x, y, z, w = pin.Quaternion(pose.rotation).coeffs()
        spec.worldbody.add_geom(name="plate", type=mujoco.mjtGeom.mjGEOM_MESH, meshname="plate",
                                pos=pose.translation, quat=[w, x, y, z])
        return "plate"

    arm = MinkArm(scene.robot, DT, add_plate)
    limit = CollisionLimit(scene.robot, scene.obstacles)
    qs, us = run_scene(scene, lambda q, target, velocity: arm.step(q, target))
    return mesh_row(scene, True, qs, us, Checker(scene.robot, scene.obstacles, limit.pair_names),
                    None, "mink")


def mink_mesh(progress: Callable[[MeshRow], object] | None = None) -> list[MeshRow]:
    """:func:`mink_pull` (the plate as its hull: MuJoCo has no other way); empty without
    mink."""
    if not available():
        return []
    rows = [mink_pull()]
    if progress is not None:
        progress(rows[0])
    return rows

