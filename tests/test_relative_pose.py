"""A task over two frames: RelativePoseTask on a Y-shaped tree whose two branches must both
move (rows against finite differences, step() and solve() to 1e-10), and two tasks on one
frame sharing its target."""

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt

H = 1e-6
AXES = ["0 0 1", "0 1 0", "1 0 0", "0 1 0"]


def branch(side: str, y: float) -> str:
    """Four revolute joints from the hub, ending in a tool frame ``<side>_tool``."""
    parts, parent = [], "hub"
    for i, axis in enumerate(AXES):
        link = f"{side}{i}"
        xyz = f"0 {y} 0.1" if i == 0 else "0.2 0 0"
        parts.append(f"""
  <link name="{link}"/>
  <joint name="{side}_j{i}" type="revolute">
    <parent link="{parent}"/><child link="{link}"/>
    <origin xyz="{xyz}" rpy="0 0 0"/><axis xyz="{axis}"/>
    <limit lower="-3" upper="3" effort="1" velocity="3"/>
  </joint>""")
        parent = link
    parts.append(f"""
  <link name="{side}_tool"/>
  <joint name="{side}_tool_joint" type="fixed">
    <parent link="{parent}"/><child link="{side}_tool"/><origin xyz="0.1 0 0" rpy="0 0 0"/>
  </joint>""")
    return "".join(parts)


Y_TREE = f"""<?xml version="1.0"?>
<robot name="y_tree">
  <link name="base"/>
  <link name="hub"/>
  <joint name="trunk" type="revolute">
    <parent link="base"/><child link="hub"/><origin xyz="0 0 0.3" rpy="0 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="3"/>
  </joint>{branch("left", 0.15)}{branch("right", -0.15)}
</robot>"""


@pytest.fixture(scope="module")
def tree():
    return sjt.Robot.from_urdf(Y_TREE, ee_frame="left_tool", load_visuals=False)


def task_on(robot):
    return sjt.RelativePoseTask("left_tool", "right_tool").bind(robot)


def rows(robot, task, q, target):
    kinematics = sjt.Kinematics(robot.model)
    kinematics.update(q)
    J, e, _ = task.compute(kinematics, target, None)
    return J.copy(), e.copy()


def relative(robot, q):
    return robot.fk(q, "right_tool").actInv(robot.fk(q, "left_tool"))


def branch_indices(robot, side):
    return [robot.model.joints[robot.model.getJointId(f"{side}_j{i}")].idx_v
            for i in range(len(AXES))]


def test_rows_against_finite_differences_of_the_error(tree, rng):
    """d e/dq by central differences on the manifold equals -Jlog6(M) Ad(M^-1) J with
    M = aMb^-1 aMd, and minus the task's error_jacobian (the search's model); the trunk that
    carries both frames has zero columns."""
    task = task_on(tree)
    for _ in range(3):
        q = tree.random_configuration(rng)
        target = relative(tree, tree.random_configuration(rng))
        J, e = rows(tree, task, q, target)
        assert np.linalg.norm(e) > 0.05
        finite = np.empty((6, tree.nv))
        for i in range(tree.nv):
            dv = np.zeros(tree.nv)
            dv[i] = H
            _, plus = rows(tree, task, pin.integrate(tree.model, q, dv), target)
            _, minus = rows(tree, task, pin.integrate(tree.model, q, -dv), target)
            finite[:, i] = (plus - minus) / (2 * H)
        M = relative(tree, q).actInv(target)
        np.testing.assert_allclose(finite, -pin.Jlog6(M) @ M.inverse().action @ J, atol=1e-6)
        np.testing.assert_allclose(task.error_jacobian(J), -finite, atol=1e-6)
        trunk = tree.model.joints[tree.model.getJointId("trunk")].idx_v
        assert np.abs(J[:, trunk]).max() < 1e-12


def test_only_the_joints_of_one_branch_are_the_task_s(tree):
    task = task_on(tree)
    joints = {tree.model.names[j] for j in task.joints(tree.model)}
    assert joints == {f"{side}_j{i}" for side in ("left", "right") for i in range(len(AXES))}


@pytest.mark.parametrize("method", ["sjt", "dls", "jp"])
def test_step_converges_with_both_branches_moving(tree, method, rng):
    q0 = tree.random_configuration(rng) * 0.5
    goal = tree.random_configuration(rng) * 0.5
    target = relative(tree, goal)
    solver = sjt.make_solver(method, tree, dt=1e-3, task=sjt.RelativePoseTask("left_tool",
                                                                              "right_tool"))
    q = q0.copy()
    for _ in range(4000):
        q = solver.step(q, target)
    assert solver.error_norm < 1e-10
    M = relative(tree, q).actInv(target)
    assert np.linalg.norm(pin.log6(M).vector) < 1e-10  # measured, not the solver's word
    for side in ("left", "right"):
        idx = branch_indices(tree, side)
        assert np.abs(q[idx] - q0[idx]).max() > 1e-2, f"the {side} branch did not move"


def test_solve_reaches_a_relative_pose(tree, rng):
    solver = sjt.SJTSolver(tree, task=sjt.RelativePoseTask("left_tool", "right_tool"))
    target = relative(tree, tree.random_configuration(rng) * 0.5)
    result = solver.solve(target, tree.q0)
    assert result.success
    assert np.linalg.norm(pin.log6(relative(tree, result.q).actInv(target)).vector) < 1e-6


def test_a_relative_task_beside_a_pose_task_takes_its_own_key(tree, rng):
    """Stacked with a world pose task on the right tool, the mapping is keyed by the relative
    task's name; both hold."""
    tasks = [sjt.PoseTask(frame="right_tool"), sjt.RelativePoseTask("left_tool", "right_tool")]
    solver = sjt.SJTSolver(tree, dt=1e-3, task=tasks)
    goal = tree.random_configuration(rng) * 0.3
    targets = {"right_tool": tree.fk(goal, "right_tool"),
               "left_tool in right_tool": relative(tree, goal)}
    q = tree.q0.copy()
    for _ in range(4000):
        q = solver.step(q, targets)
    assert solver.error_norm < 1e-10
    with pytest.raises(ValueError, match="left_tool in right_tool"):
        solver.step(q, {"right_tool": targets["right_tool"]})


def test_two_tasks_on_one_frame_share_its_target(tree, rng):
    """A position task and a low-weight orientation task on one frame take one pose."""
    tasks = [sjt.PositionTask(frame="left_tool"),
             sjt.OrientationTask(frame="left_tool", weight=0.1)]
    solver = sjt.SJTSolver(tree, dt=1e-3, task=tasks)
    target = tree.fk(tree.random_configuration(rng) * 0.4, "left_tool")
    q = tree.q0.copy()
    for _ in range(4000):
        q = solver.step(q, target)
    M = tree.fk(q, "left_tool").actInv(target)
    assert np.linalg.norm(pin.log6(M).vector) < 1e-9
    q2 = sjt.SJTSolver(tree, dt=1e-3, task=tasks).step(tree.q0, {"left_tool": target})
    np.testing.assert_array_equal(q2, sjt.SJTSolver(tree, dt=1e-3, task=tasks).step(tree.q0,
                                                                                    target))


def test_bad_frames_are_named(tree):
    with pytest.raises(ValueError, match="differ"):
        sjt.RelativePoseTask("left_tool", "left_tool")
    with pytest.raises(sjt.FrameNotFound):
        sjt.SJTSolver(tree, task=sjt.RelativePoseTask("left_tool", "nowhere"))
