"""A seed outside the position limits: ``solve()`` clips it into range first and says so
(``IKResult.clipped``); ``step()`` brings the joint back at its recovery speed, ramped within the
acceleration (and jerk) limits, and says so (``StepInfo.outside_limits``). Before, ``solve()``
from a seed out of range returned configurations out of range (253 of 1,000 random URDFs whose
neutral configuration lies outside a joint's range)."""

from pathlib import Path

import numpy as np
import pytest

import sjt_pin as sjt

#: a 3-joint arm whose neutral configuration (0) lies outside every joint's range
OFFSET_RANGES = """<robot name="offset"><link name="l0"/><link name="l1"/><link name="l2"/>
  <link name="l3"/><link name="tip"/>
  <joint name="a" type="revolute"><parent link="l0"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="0.5" upper="1.5" effort="1" velocity="1"/></joint>
  <joint name="b" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.4 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-1.5" upper="-0.2" effort="1" velocity="1"/></joint>
  <joint name="c" type="prismatic"><parent link="l2"/><child link="l3"/><origin xyz="0.3 0 0"/>
    <axis xyz="1 0 0"/><limit lower="0.1" upper="0.3" effort="1" velocity="0.2"/></joint>
  <joint name="t" type="fixed"><parent link="l3"/><child link="tip"/>
    <origin xyz="0.1 0 0"/></joint></robot>"""


@pytest.fixture(scope="module")
def offset() -> sjt.Robot:
    return sjt.Robot.from_urdf(OFFSET_RANGES, ee_frame="tip")


def inside(robot, q) -> bool:
    return bool(np.all(q >= robot.lower_limits) and np.all(q <= robot.upper_limits))


@pytest.mark.parametrize("task", [sjt.PoseTask(), sjt.PositionTask()])
def test_solve_from_any_seed_ends_within_the_limits(offset, task, rng):
    solver = sjt.SJTSolver(offset, task=task)
    for _ in range(20):
        goal = offset.random_configuration(rng)
        target = offset.fk(goal)
        target = target.translation if isinstance(task, sjt.PositionTask) else target
        seed = rng.uniform(-4, 4, offset.nq)
        result = solver.solve(target, seed)
        assert inside(offset, result.q), (seed, result)
        expected = tuple(name for name, x, lo, hi in zip("abc", seed, offset.lower_limits,
                                                         offset.upper_limits, strict=True)
                         if not lo <= x <= hi)
        assert result.clipped == expected
        assert result.success


def test_solve_from_the_neutral_configuration_outside_every_range(offset):
    target = offset.fk(np.array([1.0, -0.7, 0.2]))
    result = sjt.SJTSolver(offset).solve(target, np.zeros(3))
    assert result.clipped == ("a", "b", "c") and result.success and inside(offset, result.q)
    within = sjt.SJTSolver(offset).solve(target, np.array([1.0, -1.0, 0.15]))
    assert within.clipped == ()


def test_solve_many_reports_the_clipped_seeds(offset):
    solver = sjt.SJTSolver(offset)
    targets = [offset.fk(np.array([1.0, -0.7, 0.2]))] * 2
    results = sjt.solve_many(solver, targets, np.zeros(3), processes=1, progress=False)
    assert [r.clipped for r in results] == [("a", "b", "c")] * 2


@pytest.mark.parametrize("options", [{}, {"acceleration_limits": 2.0},
                                     {"acceleration_limits": 2.0, "jerk_limits": 50.0}])
def test_step_brings_a_seed_back_without_a_jump(offset, options):
    dt = 1e-2
    solver = sjt.SJTSolver(offset, dt=dt, **options)
    target = offset.fk(np.array([1.0, -0.7, 0.2]))
    q = np.array([2.0, 0.5, 0.6])  # every joint above its range
    path = [q]
    flags = []
    for _ in range(2000):
        q = solver.step(q, target)
        flags.append(solver.last.outside_limits)
        path.append(q)
    path = np.array(path)
    v = np.diff(path, axis=0) / dt
    assert flags[0] == ("a", "b", "c") and flags[-1] == ()
    assert all(inside(offset, x) for x in path[np.argmin([f != () for f in flags]) + 1:])
    if "jerk_limits" not in options:  # (with this jerk limit the loop circles the target)
        assert solver.error_norm < 1e-6
    assert np.all(np.abs(v) <= offset.velocity_limits * (1 + 1e-9))
    # while outside, a joint only moves toward its range
    for i, (name, hi) in enumerate(zip("abc", offset.upper_limits, strict=True)):
        out = path[:-1, i] > hi
        assert np.all(v[out, i] <= 1e-12), name
    if "acceleration_limits" in options:
        a = np.diff(v, axis=0) / dt
        assert np.abs(v[0]).max() <= 2.0 * dt * (1 + 1e-9)  # from rest: no jump
        assert np.abs(a).max() <= 2.0 * (1 + 1e-9)
    if "jerk_limits" in options:
        assert np.abs(np.diff(a, axis=0) / dt).max() <= 50.0 * (1 + 1e-9)


def test_a_joint_no_task_moves_is_named_and_a_posture_task_brings_it_back():
    gripper = sjt.Robot.from_urdf(Path(__file__).parent / "fixtures" / "mimic" / "gripper.urdf",
                                  ee_frame="tcp")
    target = gripper.fk(np.array([0.5, 0.4, 0.3, 0.01]))
    start = np.array([0.3, 0.3, 0.2, 0.05])  # the finger (off the tool's chain) out of range
    alone = sjt.SJTSolver(gripper, dt=1e-2)
    with_posture = sjt.SJTSolver(gripper, dt=1e-2, posture=sjt.PostureTask(weight=1e-2))
    for solver in (alone, with_posture):
        q = start
        for _ in range(100):
            if solver is alone and q is start:  # the first step says the finger stays out
                with pytest.warns(UserWarning, match="no task moves them"):
                    q = solver.step(q, target)
            q = solver.step(q, target)
        if solver is alone:  # the task is met; the finger, which no task moves, stays out
            assert solver.error_norm < 1e-6 and q[3] == 0.05
    # the right finger mimics the left one (at -0.05, past its own -0.04): named too
    assert alone.last.outside_limits == ("left_finger", "right_finger")
    assert with_posture.last.outside_limits == () and 0.0 <= q[3] <= 0.04
