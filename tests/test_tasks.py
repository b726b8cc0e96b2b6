"""Every task's Jacobian rows against finite differences on the manifold, away from zero error."""

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt

from .test_robot import CONTINUOUS_PRISMATIC

H = 1e-6


def robots():
    mixed = sjt.Robot.from_urdf(CONTINUOUS_PRISMATIC, ee_frame="tip", load_visuals=False)
    return {"ur5": sjt.Robot.from_example("ur5"), "panda": sjt.Robot.from_example("panda"),
            "continuous + prismatic": mixed}


TASKS = {
    "pose": lambda: sjt.PoseTask(weight=[1, 2, 1, 0.5, 1, 3]),
    "position": lambda: sjt.PositionTask(),
    "position yz": lambda: sjt.PositionTask(axes="yz"),
    "orientation": lambda: sjt.OrientationTask(),
    "posture": lambda: sjt.PostureTask(weight=0.3),
}


def rows(robot, task, q, target):
    kinematics = sjt.Kinematics(robot.model)
    kinematics.update(q)
    J, e, _ = task.compute(kinematics, target, None)
    return J.copy(), e.copy()


@pytest.fixture(scope="module")
def all_robots():
    return robots()


def far_target(robot, task, rng):
    """The pose of the task's frame at a random configuration (a posture task: its q_ref set
    to one, and no target)."""
    if task.takes_target:
        return task.target(robot.fk(robot.random_configuration(rng), task.frame))
    task.q_ref = robot.random_configuration(rng)
    return None


def error_derivative(robot, task, q, target):
    """d e / d q from J exactly, away from zero error: -J for position and posture rows;
    -Jlog(M) Ad(M^-1) J for pose rows (M = oMf^-1 oMd) and its rotation part for orientation."""
    J, _ = rows(robot, task, q, target)
    if isinstance(task, (sjt.PositionTask, sjt.PostureTask)):
        return -J
    fMd = robot.fk(q, task.frame).actInv(target)
    if isinstance(task, sjt.PoseTask):
        return -pin.Jlog6(fMd) @ fMd.inverse().action @ J
    return -pin.Jlog3(fMd.rotation) @ fMd.rotation.T @ J


@pytest.mark.parametrize("task_name", sorted(TASKS))
@pytest.mark.parametrize("robot_name", ["ur5", "panda", "continuous + prismatic"])
def test_rows_against_finite_differences_of_the_error(all_robots, robot_name, task_name, rng):
    """The error's finite differences on the manifold (q (+) h e_i), at targets far from the
    frame (|e| of order 1), equal its derivative from the task's rows J."""
    robot = all_robots[robot_name]
    task = TASKS[task_name]().bind(robot)
    for _ in range(3):
        q, target = robot.random_configuration(rng), far_target(robot, task, rng)
        _, e = rows(robot, task, q, target)
        assert np.linalg.norm(e) > 0.05  # well away from zero error
        finite = np.empty((task.dim, robot.nv))
        for i in range(robot.nv):
            dv = np.zeros(robot.nv)
            dv[i] = H
            _, plus = rows(robot, task, pin.integrate(robot.model, q, dv), target)
            _, minus = rows(robot, task, pin.integrate(robot.model, q, -dv), target)
            finite[:, i] = (plus - minus) / (2 * H)
        np.testing.assert_allclose(finite, error_derivative(robot, task, q, target), atol=1e-6)


@pytest.mark.parametrize("task_name", ["position", "position yz", "orientation", "posture"])
def test_the_transpose_direction_is_the_gradient_for_position_and_orientation(all_robots,
                                                                              task_name, rng):
    """-J^T e is the exact gradient of 1/2 |e|^2 for position, orientation (Jlog3^T log3 =
    log3, and R e = e for the rotation about e) and posture rows; for pose rows only to first
    order in |e| (on SE(3), Jlog6^T log6 != log6)."""
    robot = all_robots["panda"]
    task = TASKS[task_name]().bind(robot)
    q, target = robot.random_configuration(rng), far_target(robot, task, rng)
    J, e = rows(robot, task, q, target)
    np.testing.assert_allclose(e @ error_derivative(robot, task, q, target), -e @ J, atol=1e-9)


@pytest.mark.parametrize("task_name", ["pose", "position", "position yz", "orientation"])
@pytest.mark.parametrize("robot_name", ["ur5", "panda", "continuous + prismatic"])
def test_rows_are_the_derivative_of_the_measured_quantity(all_robots, robot_name, task_name,
                                                          rng):
    """J dq is the first-order motion of the frame: the error toward a target that moves
    with the frame changes by -J dq (finite differences on the manifold, q (+) h e_i)."""
    robot = all_robots[robot_name]
    task = TASKS[task_name]().bind(robot)
    q = robot.random_configuration(rng)
    here = robot.fk(q, task.frame)
    J, e0 = rows(robot, task, q, task.target(here))
    assert np.linalg.norm(e0) < 1e-12
    for i in range(robot.nv):
        dv = np.zeros(robot.nv)
        dv[i] = H
        _, plus = rows(robot, task, pin.integrate(robot.model, q, dv), task.target(here))
        _, minus = rows(robot, task, pin.integrate(robot.model, q, -dv), task.target(here))
        np.testing.assert_allclose((plus - minus) / (2 * H), -J[:, i], atol=1e-6)


@pytest.mark.parametrize("task_name", sorted(TASKS))
@pytest.mark.parametrize("robot_name", ["ur5", "panda", "continuous + prismatic"])
def test_error_jacobian_is_the_exact_derivative_far_from_the_target(all_robots, robot_name,
                                                                   task_name, rng):
    """``task.error_jacobian(J)`` (the set-point search's model) is minus the error's finite
    differences on the manifold at targets far from the frame, where the rows J of a pose
    or orientation task alone are not (checked: the test tells them apart)."""
    robot = all_robots[robot_name]
    task = TASKS[task_name]().bind(robot)
    for _ in range(3):
        q, target = robot.random_configuration(rng), far_target(robot, task, rng)
        kinematics = sjt.Kinematics(robot.model)
        kinematics.update(q)
        J, _, _ = task.compute(kinematics, target, None)
        exact = task.error_jacobian(J.copy())
        np.testing.assert_allclose(exact, -error_derivative(robot, task, q, target), atol=1e-9)
        if task_name in ("pose", "orientation") and robot_name != "continuous + prismatic":
            assert np.abs(exact - J).max() > 1e-2  # (that arm turns about one axis only)



def test_an_orientation_task_takes_a_rotation_matrix_as_its_target(ur5):
    """A 3x3 rotation is the same target as a pose with that rotation (the steps are the same,
    bitwise, and solve() and move_to() take it too); a matrix that is no rotation, or not
    numbers, is refused, naming what was expected."""
    goal = ur5.fk(ur5.random_configuration(np.random.default_rng(3)))
    as_pose, as_rotation = (sjt.SJTSolver(ur5, task=sjt.OrientationTask()) for _ in range(2))
    qa = qb = ur5.q0
    for _ in range(300):
        qa, qb = as_pose.step(qa, goal), as_rotation.step(qb, goal.rotation)
    np.testing.assert_array_equal(qa, qb)
    assert as_rotation.error_norm < 1e-9
    assert as_rotation.solve(goal.rotation, ur5.q0).success
    as_rotation.move_to(ur5.q0, goal.rotation)
    with pytest.raises(ValueError, match="not a rotation matrix"):
        as_rotation.step(qb, 2.0 * np.eye(3))
    with pytest.raises(ValueError, match="NaN or inf"):
        as_rotation.step(qb, np.full((3, 3), np.nan))
    with pytest.raises(ValueError, match="a 3x3 rotation"):
        as_rotation.step(qb, [["a"] * 3] * 3)
