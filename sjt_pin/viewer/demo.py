"""The demo's scene: the robots side by side, each replaying its runs of every method in turn.

The robots stand in a row along the world y axis. Each one gets the width it sweeps (its frames
at the start and the paths of its runs, plus a margin for the links' thickness), and a gap
separates it from the next. The paper's planar arm moves in its x-y plane; it is stood up so that
this plane is the vertical y-z plane, facing the camera, with its y axis pointing up.

Behind the row a Panda passes a ball (:func:`obstacle_scene`). Around them stand the whole-body
scenes (:func:`humanoid_scene`, :func:`quadruped_scene`): TALOS reaching with both hands over
its held soles, farther behind, and Solo-12 moving its body over its held feet, in front, each
with its support polygon and its centre of mass's ground projection drawn.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from ..robot import Robot
from ..tracking import TrackingLog
from ..trajectories import min_jerk
from .viewer import Viewer

#: How the demo names its robots on the page.
LABELS = {"planar3": "Planar 3R arm", "ur5": "UR5", "panda": "Franka Panda"}
#: What each robot's task controls.
TASKS = {"planar3": "x-y position", "ur5": "pose", "panda": "pose"}
#: The planar arm stood up: its x axis along world y, its y axis up (world z).
STAND_UP = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
#: Why SJT is the default though JP tracks these circles best (docs/benchmarks.md).
WHY_SJT = ("JP tracks these circles best; SJT is the default because its stable gain does not "
           "depend on the robot's size or unit, it rests at targets out of reach and it leaves "
           "saddles.")
GAP = 0.2  # m between the widths of two robots
MARGIN = 0.1  # m added on each side of a robot's frames and paths for the links' thickness
FRONT = -1.2  # m along world x from the row to the collision scene's robot (behind it)


@dataclass
class ObstacleScene:
    """The demo's collision scene: ``robot`` with ``limit`` (a CollisionLimit) around its
    ``obstacles``, and its runs (label -> log), replayed with the closest-point segments."""

    robot: Robot
    obstacles: list
    limit: object
    logs: dict


#: The node and label of the demo's collision scene.
OBSTACLE_NODE, OBSTACLE_LABEL = "panda_ball", "Franka Panda around a ball"
#: Where the whole-body scenes stand, m along world x from the row: ``"behind"`` twice as far
#: as the collision scene, leftward from its left side (a humanoid there rises above the row
#: and hides none of it); ``"ahead"`` toward the camera, rightward from the middle of the gap
#: between the row's last two robots (a small quadruped there hides none of them).
BEHIND, AHEAD = 2 * FRONT, 0.45


@dataclass
class WholeBodyScene:
    """A whole-body run of the demo: ``robot`` on its ``support`` (the
    :class:`~sjt_pin.SupportLimit` that held it), its run ``log`` (its first task frame, or its
    centre of mass, as position and target) and the ``targets`` (N, 3) of further task frames,
    shown under the node ``node`` as ``label``, ``place``d ``"behind"`` or ``"ahead"`` of the
    row (:func:`demo_viewer`)."""

    robot: Robot
    log: TrackingLog
    support: object
    node: str
    label: str
    place: str
    targets: dict = field(default_factory=dict)


#: TALOS' soles and hands, Solo-12's feet (example-robot-data's frame names).
SOLES = ("left_sole_link", "right_sole_link")
HANDS = ("gripper_left_base_link", "gripper_right_base_link")
FEET = ("FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT")
#: How far (m) TALOS' hands reach out from where they start (as on docs/whole-body.md's page),
#: and the time (s) of the reach out and back.
REACH = {HANDS[0]: np.array([0.1, 0.05, 0.05]), HANDS[1]: np.array([0.08, -0.05, -0.05])}
REACH_TIME = 4.0
#: Radius (m) and period (s) of the circle Solo-12's centre of mass draws over its feet, how far
#: (m) it is lowered, and the time (s) to ramp the circle in and out.
CIRCLE_RADIUS, CIRCLE_PERIOD, CROUCH, CIRCLE_RAMP, CIRCLE_TIME = 0.04, 2.0, 0.03, 1.0, 4.0
#: Solo-12's URDF gives its joints 1,000 rad/s: speeds of a real robot (base 2, joints 10).
SOLO_SPEEDS = np.r_[np.full(6, 2.0), np.full(12, 10.0)]
HUMANOID_NODE, HUMANOID_LABEL = "talos", "TALOS reaching over its soles"
QUADRUPED_NODE, QUADRUPED_LABEL = "solo12", "Solo-12 moving its body"


def _example(name: str) -> Robot:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (no end effector known: the tasks name their frames)
        return Robot.from_example(name)


def _record(solver, q0: np.ndarray, times: np.ndarray,
            targets: Callable[[float], dict], shown: str) -> tuple[TrackingLog, dict]:
    """Step ``solver`` from ``q0`` at ``times`` toward ``targets(t)`` (key -> target (3,)),
    their velocities (central differences) fed forward, as :func:`~sjt_pin.track` does;
    returns the run as a log (position and target: the key ``shown``, a frame or ``"com"``
    for the centre of mass; error: every task's target rows) and the other keys' targets
    (N, 3)."""
    robot, n, h = solver.robot, times.size, solver.dt / 2
    qs, dq = np.empty((n, robot.nq)), np.empty((n, robot.nv))
    wanted = {key: np.empty((n, 3)) for key in targets(0.0)}
    errors, scales = [], np.ones(n)
    q = q0
    for k, t in enumerate(times):
        goal, later, earlier = targets(float(t)), targets(t + h), targets(t - h)
        velocity = {key: (later[key] - earlier[key]) / (2 * h) for key in goal}
        q_next = solver.step(q, goal, velocity)
        qs[k], dq[k] = q, solver.displacement / solver.dt
        errors.append(solver.error.copy())
        scales[k] = solver.task_scale
        for key, value in goal.items():
            wanted[key][k] = value
        q = q_next
    data = robot.model.createData()
    if shown == "com":
        position = np.array([pin.centerOfMass(robot.model, data, q) for q in qs])
    else:
        frame = robot.frame_id(shown)
        position = np.empty((n, 3))
        for k, q in enumerate(qs):
            pin.forwardKinematics(robot.model, data, q)
            position[k] = pin.updateFramePlacement(robot.model, data, frame).translation
    error = np.array(errors)
    log = TrackingLog(t=times, q=qs, dq=dq, position=position, target=wanted.pop(shown),
                      error=error, error_norm=np.linalg.norm(error, axis=1), task_scale=scales,
                      method=solver.method.name, dt=solver.dt, gain=solver.gain)
    return log, wanted


def humanoid_scene(dt: float) -> WholeBodyScene:
    """TALOS reaching out 10 cm and back with both hands (:data:`REACH`, one period of a cosine
    in :data:`REACH_TIME` s) at level 1 with its centre of mass's ground position held,
    both soles held as poses at level 0 and a :class:`~sjt_pin.SupportLimit` (20 x 10 cm soles,
    2 cm margin), its posture below: docs/whole-body.md's example, out and back."""
    from ..limits.support import SupportLimit
    from ..solvers import SJTSolver
    from ..tasks import CoMTask, ContactTask, PositionTask, PostureTask

    talos = _example("talos")
    tasks: dict = {f: ContactTask(f) for f in SOLES}
    tasks.update({h: PositionTask(h, priority=1) for h in HANDS})
    tasks["com"] = CoMTask(axes="xy", priority=1)
    support = SupportLimit(list(SOLES), sole=(0.1, 0.05), margin=0.02)
    solver = SJTSolver(talos, dt=dt, task=tasks, limits=[support], posture=PostureTask())
    q0 = talos.q0.copy()
    start = {h: talos.fk(q0, h).translation.copy() for h in HANDS}
    com = pin.centerOfMass(talos.model, talos.model.createData(), q0).copy()

    def targets(t: float) -> dict:
        s = 0.5 - 0.5 * np.cos(2.0 * np.pi * t / REACH_TIME)
        return {**{h: start[h] + s * REACH[h] for h in HANDS}, "com": com}

    times = np.arange(round(REACH_TIME / dt) + 1) * dt
    log, others = _record(solver, q0, times, targets, HANDS[0])
    return WholeBodyScene(talos, log, support, HUMANOID_NODE, HUMANOID_LABEL, "behind",
                          {HANDS[1]: others[HANDS[1]]})


def quadruped_scene(dt: float) -> WholeBodyScene:
    """Solo-12's centre of mass moved in a :data:`CIRCLE_RADIUS` circle over its four feet and
    :data:`CROUCH` lower (the circle ramped in and out), at level 1 over its point feet held at
    level 0, with a :class:`~sjt_pin.SupportLimit` (2 cm margin) and a real robot's speeds."""
    from ..limits.support import SupportLimit
    from ..solvers import SJTSolver
    from ..tasks import CoMTask, ContactTask

    solo = _example("solo12")
    support = SupportLimit(list(FEET), margin=0.02)
    tasks = [ContactTask(f, point=True) for f in FEET] + [CoMTask(priority=1)]
    solver = SJTSolver(solo, dt=dt, task=tasks, limits=[support], velocity_limits=SOLO_SPEEDS)
    q0 = solo.q0.copy()
    com = pin.centerOfMass(solo.model, solo.model.createData(), q0).copy()

    def targets(t: float) -> dict:
        ramp = min_jerk(t / CIRCLE_RAMP) * min_jerk((CIRCLE_TIME - t) / CIRCLE_RAMP)
        angle = 2.0 * np.pi * t / CIRCLE_PERIOD
        return {"com": com + ramp * np.array([CIRCLE_RADIUS * np.cos(angle),
                                              CIRCLE_RADIUS * np.sin(angle), -CROUCH])}

    times = np.arange(round(CIRCLE_TIME / dt) + 1) * dt
    log, _ = _record(solver, q0, times, targets, "com")
    return WholeBodyScene(solo, log, support, QUADRUPED_NODE, QUADRUPED_LABEL, "ahead")


#: The whole-body scenes by the names ``sjt-pin demo --robot`` takes (``sjt_pin.cli.WHOLE_BODY``).
WHOLE_BODY_SCENES: dict[str, Callable[[float], WholeBodyScene]] = {
    HUMANOID_NODE: humanoid_scene, QUADRUPED_NODE: quadruped_scene}


def obstacle_scene(dt: float) -> ObstacleScene:
    """Panda's hand on a 40 cm line (2 s) past an 8 cm ball, with a
    :class:`~sjt_pin.CollisionLimit` (10 mm margin, self-collision on), as in docs/collision.md."""
    import coal

    from ..limits.collision import CollisionLimit
    from ..solvers import SJTSolver
    from ..tracking import track
    from ..trajectories import PoseInterpolation

    panda = Robot.from_example("panda")
    q0 = panda.q0.copy()
    start = panda.fk(q0)
    line = PoseInterpolation(start, pin.SE3(start.rotation, start.translation + [0, -0.4, 0]),
                             duration=2.0)
    ball = (coal.Sphere(0.04), pin.SE3(np.eye(3), start.translation + [0.0, -0.2, -0.07]))
    limit = CollisionLimit(panda, [ball], self_collision=True, margin=0.01)
    logs = {"sjt": track(SJTSolver(panda, dt=dt, limits=[limit]), line, q0, duration=2.5)}
    return ObstacleScene(panda, [ball], limit, logs)


def demo_viewer(runs: Mapping[str, tuple[Robot, Mapping[str, TrackingLog]]],
                live: bool = False, obstacle: ObstacleScene | None = None,
                whole_body: Sequence[WholeBodyScene] = ()) -> Viewer:
    """A viewer of ``runs`` (robot name -> (robot, method -> log)) laid out for the demo page,
    and of the ``obstacle`` scene (:func:`obstacle_scene`), if given, in front of the row
    (``FRONT`` m along world x, centred), where the view has room to spare; and of the
    ``whole_body`` scenes (:func:`humanoid_scene`, :func:`quadruped_scene`), each where its
    ``place`` says (:data:`BEHIND`, :data:`AHEAD`).

    ``live`` also starts the meshcat server (see :class:`Viewer`).
    """
    rotations = {name: STAND_UP if name == "planar3" else np.eye(3) for name in runs}
    spans = {name: _span(robot, logs.values(), rotations[name])
             for name, (robot, logs) in runs.items()}
    widths = [hi - lo for lo, hi in spans.values()]
    left = -(sum(widths) + GAP * (len(widths) - 1)) / 2
    edges = []  # world y of each robot's sides, along the row
    viewer = None
    for name, (robot, logs) in runs.items():
        lo, hi = spans[name]
        placement = pin.SE3(rotations[name], np.array([0.0, left - lo, 0.0]))
        edges.append((left, left + hi - lo))
        left += hi - lo + GAP
        if viewer is None:
            viewer = Viewer(robot, name=name, offset=placement, label=LABELS.get(name),
                            live=live)
        else:
            viewer.add_robot(robot, name, offset=placement, label=LABELS.get(name))
        viewer.compare(logs, robot=name)
    behind = 0.0  # world y of the right edge of the next scene behind the row
    if obstacle is not None:
        lo, hi = _span(obstacle.robot, obstacle.logs.values(), np.eye(3))
        placement = pin.SE3(np.eye(3), np.array([FRONT, -(lo + hi) / 2, 0.0]))
        behind = -(hi - lo) / 2
        if viewer is None:
            viewer = Viewer(obstacle.robot, name=OBSTACLE_NODE, offset=placement,
                            label=OBSTACLE_LABEL, live=live)
        else:
            viewer.add_robot(obstacle.robot, OBSTACLE_NODE, offset=placement,
                             label=OBSTACLE_LABEL)
        for i, (shape, pose) in enumerate(obstacle.obstacles):
            viewer.add_obstacle(shape, pose, f"obstacle_{i}", robot=OBSTACLE_NODE)
        end = 0.0
        for label, log in obstacle.logs.items():
            end = viewer.animate(log, robot=OBSTACLE_NODE, start=end, label=label,
                                 collision=obstacle.limit)
    gap = (edges[-2][1] + edges[-1][0]) / 2 if len(edges) > 1 else 0.0  # (of the last two)
    ahead = None  # world y of the right edge of the last scene ahead of the row
    for scene in whole_body:
        lo, hi = _span(scene.robot, [scene.log], np.eye(3))
        if scene.place == "behind":
            x, y, behind = BEHIND, behind - GAP - hi, behind - GAP - (hi - lo)
        elif scene.place == "ahead":
            if ahead is None:  # the first one centred on the gap
                ahead = gap - (hi - lo) / 2 - GAP
            x, y, ahead = AHEAD, ahead + GAP - lo, ahead + GAP + hi - lo
        else:
            raise ValueError(f"place must be 'behind' or 'ahead', got {scene.place!r}")
        placement = pin.SE3(np.eye(3), np.array([x, y, 0.0]))
        if viewer is None:
            viewer = Viewer(scene.robot, name=scene.node, offset=placement, label=scene.label,
                            live=live)
        else:
            viewer.add_robot(scene.robot, scene.node, offset=placement, label=scene.label)
        viewer.animate(scene.log, robot=scene.node, label=scene.log.method,
                       targets=scene.targets, support=scene.support)
    if viewer is None:
        raise ValueError("runs must hold at least one robot")
    return viewer


def describe(names: Sequence[str], dt: float, obstacle: bool = False) -> str:
    """The page's description of the demo's runs on the robots ``names`` (none: the page has
    no circles), period ``dt`` (s), and of the collision scene if ``obstacle``."""
    text = ""
    if names:
        tasks = "; ".join(f"{LABELS.get(n, n)}: {TASKS.get(n, 'its task')}" for n in names)
        text = f"Each robot tracks a circle with each method in turn ({1e3 * dt:g} ms; {tasks}). "
        text += WHY_SJT
    if obstacle:
        text += (" Behind: a Panda passes a ball, 10 mm margin (47 mm deep without the limit); "
                 "crimson: the closest points.")
    return text.strip()


def _span(robot: Robot, logs: Iterable[TrackingLog],
          rotation: np.ndarray) -> tuple[float, float]:
    """Lowest and highest world y (m) of ``robot``'s frames at its runs' start and of their
    paths, with its base rotated by ``rotation`` and at the origin, widened by MARGIN."""
    logs = list(logs)
    data = robot.model.createData()
    points = [log.position for log in logs] + [log.target for log in logs]
    for q in [log.q[0] for log in logs] or [robot.q0]:
        pin.framesForwardKinematics(robot.model, data, q)
        points.append(np.array([frame.translation for frame in data.oMf]))
    y = np.concatenate(points) @ rotation[1]
    return float(y.min()) - MARGIN, float(y.max()) + MARGIN
