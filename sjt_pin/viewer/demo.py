"""The demo's scene: the robots side by side, each replaying its runs of every method in turn.

The robots stand in a row along the world y axis. Each one gets the width it sweeps (its frames
at the start and the paths of its runs, plus a margin for the links' thickness), and a gap
separates it from the next. The paper's planar arm moves in its x-y plane; it is stood up so that
this plane is the vertical y-z plane, facing the camera, with its y axis pointing up.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..robot import Robot
from ..tracking import TrackingLog
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
                live: bool = False, obstacle: ObstacleScene | None = None) -> Viewer:
    """A viewer of ``runs`` (robot name -> (robot, method -> log)) laid out for the demo page,
    and of the ``obstacle`` scene (:func:`obstacle_scene`), if given, in front of the row
    (``FRONT`` m along world x, centred), where the view has room to spare.

    ``live`` also starts the meshcat server (see :class:`Viewer`).
    """
    rotations = {name: STAND_UP if name == "planar3" else np.eye(3) for name in runs}
    spans = {name: _span(robot, logs.values(), rotations[name])
             for name, (robot, logs) in runs.items()}
    widths = [hi - lo for lo, hi in spans.values()]
    left = -(sum(widths) + GAP * (len(widths) - 1)) / 2
    viewer = None
    for name, (robot, logs) in runs.items():
        lo, hi = spans[name]
        placement = pin.SE3(rotations[name], np.array([0.0, left - lo, 0.0]))
        left += hi - lo + GAP
        if viewer is None:
            viewer = Viewer(robot, name=name, offset=placement, label=LABELS.get(name),
                            live=live)
        else:
            viewer.add_robot(robot, name, offset=placement, label=LABELS.get(name))
        viewer.compare(logs, robot=name)
    if obstacle is not None:
        lo, hi = _span(obstacle.robot, obstacle.logs.values(), np.eye(3))
        placement = pin.SE3(np.eye(3), np.array([FRONT, -(lo + hi) / 2, 0.0]))
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
    if viewer is None:
        raise ValueError("runs must hold at least one robot")
    return viewer


def describe(names: Sequence[str], dt: float, obstacle: bool = False) -> str:
    """The page's description of the demo's runs on the robots ``names``, period ``dt`` (s),
    and of the collision scene if ``obstacle``."""
    tasks = "; ".join(f"{LABELS.get(n, n)}: {TASKS.get(n, 'its task')}" for n in names)
    text = f"Each robot tracks a circle with each method in turn ({1e3 * dt:g} ms; {tasks}). "
    text += WHY_SJT
    if obstacle:
        text += (" Behind: a Panda passes a ball, 10 mm margin (47 mm deep without the limit); "
                 "crimson: the closest points.")
    return text


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
