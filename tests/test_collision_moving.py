"""CollisionLimit with moving obstacles: ``move(i, pose, velocity=)`` (or time-stamped poses,
``time=``) makes each row bound the relative closing speed of its pair (the obstacle's normal
velocity at its closest point is added to the bound), so an arm gives way to an obstacle
driven at it as far as its limits allow, and ``StepInfo.rows_exceeded`` says by how much it
could not."""

from __future__ import annotations

import copy
import pickle

import coal
import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin import kernels
from sjt_pin.bench import collision_moving as moving
from sjt_pin.limits import CollisionLimit
from sjt_pin.limits.base import Motion
from sjt_pin.limits.collision import BRAKING_SHARE, EASING_SLACK

MARGIN = 0.01


def _rows(limit, robot, q, dt=1e-3):
    """The limit's rows at q without speed limits (every pair within influence has one):
    {pair index: b} of the pairs' own rows."""
    kinematics = sjt.Kinematics(robot.model)
    kinematics.update(q)
    motion = Motion(q=q, dq=np.zeros(robot.nv), ddq=np.zeros(robot.nv), dt=dt)
    out = limit.rows(kinematics, motion)
    assert out is not None
    return dict(zip(limit.active, out[1][:len(limit.active)], strict=True))


def _distances(limit, q):
    return {(p.a, p.b): p.distance for p in limit.distances(q)}


@pytest.mark.parametrize("shape", [coal.Box(0.1, 0.2, 0.05), coal.Capsule(0.04, 0.2),
                                   coal.Sphere(0.05)])
def test_each_row_moves_its_bound_by_the_obstacles_normal_velocity(panda, shape):
    """A translating and turning obstacle near Panda's hand: each pair row's bound changes
    by the rate at which the obstacle's motion alone changes the pair's distance (finite
    differences of coal's distance, the obstacle carried along its twist, the robot still)."""
    q = panda.q0.copy()
    hand = panda.fk(q).translation
    rng = np.random.default_rng(3)
    pose = pin.SE3(pin.exp3(rng.normal(size=3)), hand + np.array([0.17, 0.0, -0.05]))
    limit = CollisionLimit(panda, [(shape, pose)], margin=MARGIN, influence=0.2, witnesses=0)
    still = _rows(limit, panda, q)
    twist = np.r_[rng.normal(size=3) * 0.3, rng.normal(size=3) * 2.0]
    limit.move(0, pose, velocity=twist)
    carried = _rows(limit, panda, q)
    assert set(carried) == set(still) and still
    h = 1e-6
    moved = pin.SE3(pin.exp3(twist[3:] * h) @ pose.rotation, pose.translation + twist[:3] * h)
    before = _distances(limit, q)
    limit.move(0, moved)
    after = _distances(limit, q)
    names = limit.pair_names
    for k in still:
        rate = (after[names[k]] - before[names[k]]) / h
        assert carried[k] - still[k] == pytest.approx(rate, abs=1e-4)


def test_velocity_is_checked_and_copied(panda):
    limit = CollisionLimit(panda, [(coal.Sphere(0.05), pin.SE3(np.eye(3), np.ones(3)))])
    pose = pin.SE3(np.eye(3), np.ones(3))
    for bad, error in (([1.0, 2.0], ValueError), ([np.nan] * 6, ValueError),
                       ("fast", TypeError), ([1, 2, 3, 4, 5, "x"], TypeError)):
        with pytest.raises(error, match="velocity of obstacle 0"):
            limit.move(0, pose, velocity=bad)
    with pytest.raises(TypeError, match="index"):
        limit.move(True, pose)
    with pytest.raises(ValueError, match="not finite"):
        limit.move(0, pin.SE3(np.eye(3), np.array([np.nan, 0.0, 0.0])))
    limit.move(0, pose, velocity=pin.Motion(np.array([1.0, 2, 3]), np.array([0.1, 0.2, 0.3])))
    np.testing.assert_array_equal(limit.velocities, [[1, 2, 3, 0.1, 0.2, 0.3]])
    for other in (copy.deepcopy(limit), pickle.loads(pickle.dumps(limit))):
        np.testing.assert_array_equal(other.velocities, limit.velocities)
    limit.move(0, pose)  # no velocity: at rest
    np.testing.assert_array_equal(limit.velocities, np.zeros((1, 6)))


def test_time_stamped_poses_give_the_velocity(panda):
    """``move(i, pose, time=t)`` without a velocity: the twist is the backward difference of
    the time-stamped poses (a constant twist's translation exactly, its rotation to rounding
    here), at rest on the first stamp; a velocity given wins; a ``move`` without ``time``
    starts the differences anew; times that do not increase, or are not numbers, are
    refused before anything changes; copies carry the last stamp."""
    start = pin.SE3(pin.exp3(np.array([0.2, -0.1, 0.3])), np.array([0.4, 0.3, 0.5]))
    limit = CollisionLimit(panda, [(coal.Sphere(0.05), start)])
    twist = np.array([0.3, -0.5, 0.1, 0.4, -0.2, 0.6])

    def at(t):
        return pin.SE3(pin.exp3(twist[3:] * t) @ start.rotation, start.translation + twist[:3] * t)

    limit.move(0, at(0.0), time=0.0)
    np.testing.assert_array_equal(limit.velocities, np.zeros((1, 6)))
    for k in range(1, 4):
        limit.move(0, at(k * 0.01), time=k * 0.01)
        np.testing.assert_allclose(limit.velocities[0], twist, rtol=0, atol=1e-12)
    for other in (copy.deepcopy(limit), pickle.loads(pickle.dumps(limit))):
        other.move(0, at(0.05), time=0.05)  # (differenced from the copied stamp at 0.03)
        np.testing.assert_allclose(other.velocities[0], twist, rtol=0, atol=1e-12)
    given = np.array([1.0, 2.0, 3.0, 0.0, 0.0, 0.0])
    limit.move(0, at(0.04), velocity=given, time=0.04)
    np.testing.assert_array_equal(limit.velocities[0], given)
    for bad, error in ((0.04, ValueError), (0.01, ValueError), (np.nan, ValueError),
                       ("now", TypeError), (True, TypeError)):
        with pytest.raises(error, match="time of obstacle 0"):
            limit.move(0, at(0.1), time=bad)
    np.testing.assert_array_equal(limit.velocities[0], given)  # (refused: nothing changed)
    limit.move(0, at(0.05), time=0.05)
    np.testing.assert_allclose(limit.velocities[0], twist, rtol=0, atol=1e-12)
    limit.move(0, at(0.06))  # no time: at rest, and the next stamp is a first one
    limit.move(0, at(0.07), time=0.07)
    np.testing.assert_array_equal(limit.velocities, np.zeros((1, 6)))


@pytest.mark.slow
@pytest.mark.parametrize("name, speed, dt, smooth", [
    ("panda", 1.0, 1e-3, False), ("panda", 0.5, 1e-2, False), ("panda", 0.5, 1e-3, True),
    ("ur5", 1.0, 1e-3, False), ("ur5", 0.5, 1e-2, False), ("ur5", 0.5, 1e-3, True)])
def test_an_arm_gives_way_to_an_obstacle_driven_at_it(name, speed, dt, smooth):
    """A 5 cm ball driven at the hand (``sjt_pin.bench.collision_moving``): where the arm's
    limits let it retreat as fast as the ball comes, the distance stays above margin - 1 mm
    at every step, checked on the meshes, every limit within 1.01x and every row kept; without
    the velocity the same ball enters the margin."""
    robot = sjt.Robot.from_example(name)
    row = moving.drive(robot, speed, dt, smooth)
    assert row.closest >= MARGIN - 1e-3, f"{row.closest * 1e3:.2f} mm"
    assert row.speed_ratio <= 1.01
    if smooth:
        assert max(row.acceleration_ratio, row.jerk_ratio) <= 1.01
    assert row.exceeded == 0
    if name == "panda" and dt == 1e-3:
        blind = moving.drive(robot, speed, dt, smooth, told=False)
        assert blind.closest < MARGIN - 1e-3
    if smooth:  # its poses time-stamped instead of its velocity: as safe
        stamped = moving.drive(robot, speed, dt, smooth, told="time")
        assert stamped.closest >= MARGIN - 1e-3, f"{stamped.closest * 1e3:.2f} mm"
        assert max(stamped.speed_ratio, stamped.acceleration_ratio, stamped.jerk_ratio) <= 1.01
        assert stamped.exceeded == 0


def test_an_obstacle_faster_than_the_arm_is_reported(panda):
    """A ball at 3 m/s, beyond what Panda's speed limits can retreat from: the steps that
    cannot keep the rows say so in ``rows_exceeded``."""
    row = moving.drive(panda, 3.0, 1e-3, travel=0.25)
    assert row.exceeded > 0
    assert row.closest < MARGIN  # (what the report is for)


@pytest.mark.parametrize("jerk", [False, True])
def test_a_moving_obstacles_rows_brake_the_relative_speed_and_give_up_what_it_outruns(jerk):
    """``kernels.stoppable_rows`` with ``carried`` (the obstacle's normal velocity away,
    -u): a row is the still obstacle's row of an arm that closes u faster, less u (it is the
    arm's speed that brakes, the obstacle's stays); with ``speeds`` (how fast each joint can
    move down, then up), a row whose obstacle comes faster than the row's retreat within them
    (u > sum_j |A_ij| speeds[A_ij > 0 ? down : up, j]) counts u only up to that retreat, and
    ``needs`` holds the bound it would need (below the one given), NaN for the other rows."""
    rng = np.random.default_rng(11 + jerk)
    n, k, dt = 6, 120, 1e-3
    rate = 0.5 / dt
    A = rng.normal(size=(k, n)) * rng.uniform(0.01, 0.5, (k, 1))
    damper = rate * rng.uniform(-0.004, 0.3, k)
    dq, ddq = rng.normal(size=n) * 0.5, rng.normal(size=n) * 3.0
    acc = rng.uniform(5.0, 20.0, n)
    jerks = rng.uniform(2000.0, 8000.0, n) if jerk else None
    speeds = rng.uniform(0.0, 3.0, (2, n))  # (down, up: a joint near a range's end is slow)
    u = rng.uniform(-0.5, 2.0, k)

    def cut(b, dq_arm, carried=None, speeds=None, needs=None):
        b = b.copy()
        kernels.stoppable_rows(A, b, dq_arm, ddq, acc, jerks, rate, dt, BRAKING_SHARE,
                               EASING_SLACK, None, None, carried, speeds, needs)
        return b

    moving = cut(damper, dq, carried=-u)
    for i in range(k):  # (one row at a time: the arm's closing speed along it raised by u_i)
        shifted = dq + u[i] * A[i] / (A[i] @ A[i])
        still = cut(damper, shifted)[i]
        assert moving[i] == pytest.approx(still - u[i], rel=1e-9, abs=1e-9)
    retreat = np.sum(np.abs(A) * np.where(A > 0, speeds[0], speeds[1]), axis=1)
    needs = np.empty(k)
    given = cut(damper, dq, carried=-u, speeds=speeds, needs=needs)
    outrun = u > retreat
    assert 0 < outrun.sum() < k
    np.testing.assert_array_equal(np.isnan(needs), ~outrun)
    np.testing.assert_array_equal(needs[outrun], moving[outrun])
    np.testing.assert_allclose(given, cut(damper, dq, carried=-np.minimum(u, retreat)),
                               rtol=0, atol=1e-12)
    assert np.all(needs[outrun] <= given[outrun] + 1e-12)


def test_a_ball_that_outruns_a_link_leaves_the_acceleration_limits_whole(panda):
    """A 5 cm ball at 1 m/s at Panda's second link, which its joints can move away at a few
    cm/s: no step keeps that link's margin plan, so the row is given up (``needs`` below its
    bound) and the step keeps every acceleration and jerk limit (yielding them, as for a row
    the arm can keep, would throw every joint to its speed limit each period, the margin
    lost all the same), while ``StepInfo.rows_exceeded`` says the rows are not kept."""
    dt, speed = 1e-3, 1.0
    accelerations, jerks = moving.franka_like(panda.nv)
    data = panda.model.createData()
    pin.forwardKinematics(panda.model, data, panda.q0)
    start = data.oMi[panda.model.getJointId("panda_joint2")].translation + [0.0, 0.45, 0.0]
    limit = CollisionLimit(panda, [(coal.Sphere(0.05), pin.SE3(np.eye(3), start))],
                           margin=MARGIN)
    solver = sjt.make_solver("sjt", panda, dt=dt, limits=[limit],
                             acceleration_limits=accelerations, jerk_limits=jerks)
    q, qs, target = panda.q0.copy(), [panda.q0.copy()], panda.fk(panda.q0)
    exceeded = given_up = 0
    for k in range(300):
        moved = min(speed * k * dt, 0.25)
        velocity = np.r_[0.0, -speed if moved < 0.25 else 0.0, 0.0, 0.0, 0.0, 0.0]
        limit.move(0, pin.SE3(np.eye(3), start - [0.0, moved, 0.0]), velocity=velocity)
        q = solver.step(q, target)
        qs.append(q)
        exceeded += bool(solver.last.rows_exceeded)
        needs = limit.needs()
        given_up += needs is not None and bool(np.any(~np.isnan(needs)))
    v = np.diff(qs, axis=0) / dt
    a = np.diff(v, axis=0) / dt
    j = np.diff(a, axis=0) / dt
    assert np.all(np.abs(a) <= 1.01 * accelerations)
    assert np.all(np.abs(j) <= 1.01 * jerks)
    assert np.all(np.abs(v) <= 1.01 * panda.velocity_limits)
    assert given_up > 0 and exceeded > 0


def test_a_joint_near_the_end_of_its_range_retreats_no_faster_than_it_can_stop(panda):
    """The retreat a moving obstacle's row is measured against (``kernels.stoppable_rows``'
    ``speeds``): each joint's speed limit, and toward a range's end no faster than the joint
    can still stop there at its acceleration limit, sqrt(2 a room); at the end, nothing."""
    limit = CollisionLimit(panda, [(coal.Sphere(0.05), pin.SE3(np.eye(3), np.ones(3)))])
    lower, upper = panda.model.lowerPositionLimit, panda.model.upperPositionLimit
    q = panda.q0.copy()
    q[0] = lower[0]  # at its lower end
    q[3] = upper[3] - 1e-3  # 1 mrad below its upper end
    accelerations = np.full(panda.nv, 10.0)
    motion = Motion(q=q, dq=np.zeros(panda.nv), ddq=np.zeros(panda.nv), dt=1e-3,
                    acceleration_limits=accelerations, velocity_limits=panda.velocity_limits)
    speeds = limit._retreat_speeds(motion)
    expected = np.vstack([np.minimum(panda.velocity_limits, np.sqrt(20.0 * (q - lower))),
                          np.minimum(panda.velocity_limits, np.sqrt(20.0 * (upper - q)))])
    np.testing.assert_allclose(speeds, expected, rtol=1e-12)
    assert speeds[0, 0] == 0.0 and speeds[1, 0] == panda.velocity_limits[0]
    assert speeds[1, 3] == pytest.approx(np.sqrt(20.0 * 1e-3))


def _so101_forearm_ball():
    """SO-101 (example-robot-data's URDF, fixed base, the gripper locked) holding its pose, a
    5 cm ball driven at 0.5 m/s from 0.4 m at the middle of its forearm (from the side and
    above), where it stops: the upper and the lower arm cannot both give way to it."""
    from example_robot_data.robots_loader import getModelPath

    name = "so_arm_description/urdf/so101.urdf"
    robot = sjt.Robot.from_urdf(f"{getModelPath(name)}/{name}", ee_frame="gripper_frame_link",
                                locked_joints=("gripper",))
    q0 = np.array([0.0, -0.6, 0.6, 1.0, 0.0])
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, q0)
    elbow, wrist = (data.oMi[robot.model.getJointId(j)].translation
                    for j in ("elbow_flex", "wrist_flex"))
    side = np.cross(wrist - elbow, [0.0, 0.0, 1.0])
    come = side / np.linalg.norm(side) + [0.0, 0.0, 0.5]
    come /= np.linalg.norm(come)
    start = (elbow + wrist) / 2 + 0.4 * come
    path = []
    for k in range(1300):
        moved = min(0.5e-3 * k, 0.4)
        path.append((pin.SE3(np.eye(3), start - moved * come),
                     np.r_[-come * (0.5 if moved < 0.4 else 0.0), 0.0, 0.0, 0.0]))
    return robot, q0, path


def _so101_run(method, read_every=0):
    robot, q0, path = _so101_forearm_ball()
    limit = CollisionLimit(robot, [(coal.Sphere(0.05), path[0][0])], margin=MARGIN)
    accelerations, jerks = moving.franka_like(robot.nv)
    solver = sjt.make_solver(method, robot, dt=1e-3, limits=[limit],
                             acceleration_limits=accelerations, jerk_limits=jerks)
    q, qs, reported, target = q0.copy(), [q0.copy()], [], robot.fk(q0)
    for k, (pose, velocity) in enumerate(path):
        limit.move(0, pose, velocity=velocity)
        q = solver.step(q, target)
        qs.append(q)
        reported.append(bool(solver.last.limit_conflicts))
        if read_every and k % read_every == 0:
            limit.distances(q)
            limit.closest_points(q)
    return robot, np.array(qs), np.array(reported), accelerations


@pytest.mark.parametrize("method", ["sjt", "dls"])
def test_a_yield_to_the_rows_leaves_each_joint_able_to_stop_within_its_range(method):
    """Where the rows make the acceleration limits yield, each joint still moves toward the end
    of its range no faster than its limits can stop it there: SO-101's elbow, the rows
    yielding 2.2x for 300 steps to the ball at its forearm, ran on at 4 rad/s toward an end
    0.5 rad away, met it at 2.9 rad/s and stopped there in one step (280 times its
    acceleration limit, the jerk 500 times). Every step above a limit is reported, and no
    joint meets its range's end faster than one step of its acceleration limit."""
    robot, qs, reported, accelerations = _so101_run(method)
    dt = 1e-3
    v = np.diff(qs, axis=0) / dt
    a = np.diff(v, axis=0) / dt
    above = np.max(np.abs(a) / accelerations, axis=1) > 1.001
    assert not np.any(above & ~reported[1:]), np.flatnonzero(above & ~reported[1:])
    lo, hi = robot.model.lowerPositionLimit, robot.model.upperPositionLimit
    at_end = (qs[1:] >= hi - 1e-9) | (qs[1:] <= lo + 1e-9)
    assert np.all(np.abs(v[at_end]) <= (accelerations * dt * np.ones_like(v))[at_end] + 1e-9)


def test_reading_the_distances_between_steps_leaves_the_steps_as_they_were():
    """``distances()`` and ``closest_points()`` between steps use a geometry data of their
    own: in the steps' own, reading them (here at every 7th step; at six steps was enough)
    changed SO-101's path from there, bit by bit and then by 2.5x in its largest acceleration
    (coal's queries keep state from one call to the next)."""
    _, plain, _, _ = _so101_run("dls")
    _, read, _, _ = _so101_run("dls", read_every=7)
    assert np.array_equal(plain, read)
