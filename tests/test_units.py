"""SJT is unit-free: a URDF and its targets in mm give the joint trajectory of the same run in
m, for every SJT form, because the pose task weights its angular rows by a length."""

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin.bench.accuracy import baxter_arm, units
from sjt_pin.tasks.pose import characteristic_length


@pytest.fixture(scope="module")
def arms():
    return baxter_arm(1.0), baxter_arm(1000.0)


def test_the_characteristic_length_is_the_mean_reach_of_the_chain(planar3):
    # links of 0.3, 0.4 and 0.28 m and a 0.2 m gripper: 1.18, 0.88 and 0.48 m from each joint
    assert characteristic_length(planar3, planar3.ee_frame_id) == pytest.approx(
        np.mean([1.18, 0.88, 0.48]), rel=1e-12)
    task = sjt.SJTSolver(planar3, task=sjt.PositionTask(axes="xy")).stack.task
    assert characteristic_length(planar3, task.frame_id) == pytest.approx(0.8466666666666667)


def test_the_characteristic_length_scales_with_the_unit(arms):
    (metres, _), (millimetres, _) = arms
    length = characteristic_length(metres, metres.ee_frame_id)
    assert 0.5 < length < 1.0  # Baxter's arm: 0.81 m
    assert characteristic_length(millimetres, millimetres.ee_frame_id) == pytest.approx(
        1000.0 * length, rel=1e-12)


@pytest.mark.parametrize("variant", ["SJT (paper, eq. 21)", "SJT", "SJT, transpose feedback"])
def test_every_sjt_form_runs_alike_in_mm_and_in_m(variant):
    """Baxter's arm on a circle and a wrist screw at 1 and 4 ms: the same joint trajectory
    (1e-7 rad) and the same errors in the scaled unit (a ratio of 1). (Where the wrist screw
    meets a limit, the stage's projection puts the task first by a factor 1e6 over
    self-motion, so the rounding of the two units' inputs reaches the joints amplified by about
    1e3: 1e-9 to 2e-8 rad after 2.5 s, where the other steps keep 1e-13.)"""
    for row in units(variants=(variant,)):
        assert row.joint_difference < 1e-7, row
        assert row.position_ratio == pytest.approx(1.0, abs=1e-9), row
        assert row.orientation_ratio == pytest.approx(1.0, abs=1e-9), row


def test_dls_is_not_unit_free():
    """DLS's damping is a length (0.05 m on every row): in mm it damps 1000x less."""
    rows = units(dts=(4e-3,), variants=("DLS (0.05)",))
    assert max(r.joint_difference for r in rows) > 1e-3


def test_a_position_task_runs_alike_in_mm_and_in_m(arms):
    """The floor under SJT's column norms is a fraction of the tasks' length: in mm too."""
    trajectories = []
    for scale, (robot, q0) in zip((1.0, 1000.0), arms, strict=True):
        solver = sjt.SJTSolver(robot, task=sjt.PositionTask(), dt=2e-3)
        assert solver.method.length == pytest.approx(
            0.2 * characteristic_length(robot, robot.ee_frame_id), rel=1e-12)
        start = robot.fk(q0).translation
        circle = sjt.Circle(start - scale * np.array([0.0, 0.1, 0.0]), 0.1 * scale, 2.0,
                            normal=[1, 0, 0])
        trajectories.append(sjt.track(solver, circle, q0).q)
    assert np.abs(trajectories[0] - trajectories[1]).max() < 1e-9


def test_the_length_of_a_pose_task_weights_its_angular_rows(arms):
    (robot, q0), _ = arms
    default = sjt.SJTSolver(robot)
    length = characteristic_length(robot, robot.ee_frame_id)
    np.testing.assert_allclose(default.stack.sqrt_weight, [1, 1, 1, length, length, length])
    solver = sjt.SJTSolver(robot, task=sjt.PoseTask(length=0.3, weight=4.0))
    np.testing.assert_allclose(solver.stack.sqrt_weight, [2, 2, 2, 0.6, 0.6, 0.6])
    solver.step(q0, robot.fk(q0) * pin.exp6(pin.Motion(np.full(6, 0.01))))
    assert solver.last.error[3:] == pytest.approx(np.full(3, 0.01), rel=0.05)  # rad, unweighted
    oriented = sjt.SJTSolver(robot, task=sjt.OrientationTask(length=0.3))
    np.testing.assert_allclose(oriented.stack.sqrt_weight, [0.3, 0.3, 0.3])


def test_pose_length_sets_the_implicit_pose_task(arms):
    (robot, q0), _ = arms
    target = robot.fk(q0) * pin.exp6(pin.Motion(np.array([0.05, 0.0, 0.02, 0.1, 0.0, 0.2])))
    a = sjt.SJTSolver(robot, pose_length=0.25)
    b = sjt.SJTSolver(robot, task=sjt.PoseTask(length=0.25))
    assert a.stack.task.length == 0.25
    qa, qb = q0.copy(), q0.copy()
    for _ in range(200):
        qa, qb = a.step(qa, target), b.step(qb, target)
    np.testing.assert_array_equal(qa, qb)
    assert not np.array_equal(qa, sjt.SJTSolver(robot).step(q0, target))
    with pytest.raises(ValueError, match="pose_length"):
        sjt.SJTSolver(robot, task=sjt.PoseTask(), pose_length=0.25)


@pytest.mark.parametrize("bad, error", [(0.0, ValueError), (-1.0, ValueError),
                                        (float("nan"), ValueError), (float("inf"), ValueError),
                                        ("1", TypeError), (True, TypeError)])
def test_a_bad_length_is_refused_by_name(bad, error):
    with pytest.raises(error, match="length"):
        sjt.PoseTask(length=bad)
    with pytest.raises(error, match="length"):
        sjt.OrientationTask(length=bad)
