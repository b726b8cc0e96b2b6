"""Ready-made tracking scenarios on the planar arm, UR5 and Panda (demo, benchmarks, notebooks).

Each scenario is a robot, a task, a start configuration and a trajectory that starts where the
end effector is, so that the tracking error measures tracking and not an initial jump.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..robot import Robot
from ..tasks import PoseTask, PositionTask, Task
from ..trajectories import Circle, Trajectory

ROBOTS = ("planar3", "ur5", "panda")

#: Start of the paper's tasks: elbow up at (60, 45, 30) deg puts the end effector on
#: (-0.293, 0.986), the first point of the paper's Fig. 5 lines.
PLANAR3_START = np.deg2rad([60.0, 45.0, 30.0])
UR5_START = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])


@dataclass
class Scenario:
    """A robot, the task to track, the start configuration ``q0`` and the trajectory."""

    name: str
    robot: Robot
    task: Task
    q0: np.ndarray
    trajectory: Trajectory


def load_robot(name: str) -> Robot:
    """``"planar3"`` (the paper's arm) or an example-robot-data name."""
    return Robot.planar3() if name == "planar3" else Robot.from_example(name)


def scenario(name: str, robot: Robot | None = None) -> Scenario:
    """The demo scenario of ``name`` in :data:`ROBOTS`.

    - planar3: the paper's task 3, a circle of radius 0.194 m about (0, 0.986) that touches the
      boundary of the reach (1.18 m), x-y position task, 4 s per turn.
    - ur5: a 0.15 m circle in a vertical plane, full pose task, 4 s.
    - panda: a 0.2 m circle in a vertical plane in front of the robot, full pose task, 4 s.
    """
    if name not in ROBOTS:
        raise ValueError(f"name must be one of {ROBOTS}, got {name!r}")
    robot = load_robot(name) if robot is None else robot
    if name == "planar3":
        center = np.array([0.0, 0.986, 0.0])
        radius = 0.194
        # start on the circle's lowest point, (0, 0.792), from the elbow-up posture
        circle = Circle(center, radius, duration=4.0, start_angle=-np.pi / 2)
        q0 = settle(robot, PositionTask(axes="xy"), PLANAR3_START, circle.sample(0.0)[0])
        return Scenario(name, robot, PositionTask(axes="xy"), q0, circle)
    q0 = UR5_START if name == "ur5" else robot.q0
    pose = robot.fk(q0)
    radius = 0.15 if name == "ur5" else 0.2
    circle = Circle(pose.translation - [0.0, radius, 0.0], radius, duration=4.0,
                    normal=[1.0, 0.0, 0.0], rotation=pose.rotation)
    return Scenario(name, robot, PoseTask(), q0, circle)


def settle(robot: Robot, task: Task, q: np.ndarray, target: pin.SE3) -> np.ndarray:
    """``q`` moved onto ``target`` by damped least-squares iterations (to start a run on a path)."""
    from ..solvers import DLSSolver

    # the textbook DLS (no error damping): the start configurations the paper's runs had
    solver = DLSSolver(robot, gain="auto", dt=1e-2, task=task, damping=1e-3, error_damping=0.0)
    for _ in range(200):
        q = solver.step(q, target)
        if solver.last.error_norm < 1e-10:
            break
    return q
