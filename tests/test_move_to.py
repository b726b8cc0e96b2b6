"""Solver.move_to: any pose solve() reaches is reached, along a joint-space path, with every
position, speed, acceleration and jerk limit kept on every step - also from the starts where
a step loop alone stops short (a local minimum against the joint limits); the solver carries
on from the move without a jump; a target solve() cannot reach is refused by name."""

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin.bench.limits import PANDA_ACCELERATION, PANDA_JERK

LIMITS = {"panda": (PANDA_ACCELERATION, PANDA_JERK), "ur5": (10.0, 5000.0)}


def random_pair(robot, rng):
    """A start and a reachable target (fk of a random q), both over the full URDF ranges."""
    q0, q1 = robot.random_configuration(rng), robot.random_configuration(rng)
    return q0, robot.fk(q1)


def pose_error(robot, q, target):
    e = pin.log6(robot.fk(q).actInv(target)).vector
    return np.linalg.norm(e[:3]), np.linalg.norm(e[3:])


def assert_within_limits(robot, qs, dt, acceleration, jerk):
    assert np.all(qs >= robot.lower_limits - 1e-12) and np.all(qs <= robot.upper_limits + 1e-12)
    v = np.diff(qs, axis=0) / dt  # (these arms' coordinates are their tangent space)
    a = np.diff(np.vstack([np.zeros((1, robot.nv)), v]), axis=0) / dt
    j = np.diff(a, axis=0) / dt
    assert np.max(np.abs(v) / robot.velocity_limits) <= 1.01
    assert np.max(np.abs(a) / acceleration) <= 1.01
    assert np.max(np.abs(j) / jerk) <= 1.01


@pytest.mark.slow
@pytest.mark.parametrize("name", ["panda", "ur5"])
def test_move_to_reaches_what_solve_reaches_within_every_limit(name):
    robot = sjt.Robot.from_example(name)
    acceleration, jerk = (np.broadcast_to(x, robot.nv) for x in LIMITS[name])
    rng = np.random.default_rng(3)
    stuck = 0
    for _ in range(4):
        q0, target = random_pair(robot, rng)
        solver = sjt.SJTSolver(robot, acceleration_limits=acceleration, jerk_limits=jerk)
        given = q0.copy()
        move = solver.move_to(q0, target)
        q, qs = q0.copy(), [q0]
        for _ in range(int((move.duration + 1.0) / solver.dt)):
            q = move.step(q)
            qs.append(q)
            if move.done:
                break
        assert move.done, (move.time, move.last)
        np.testing.assert_array_equal(q0, given)  # the caller's q is never written
        for _ in range(100):  # the solver carries on from the move: no jump, at rest
            q = solver.step(q, target)
            qs.append(q)
        position, rotation = pose_error(robot, q, target)
        assert position < 1e-6 and rotation < 1e-6
        assert_within_limits(robot, np.array(qs), solver.dt, acceleration, jerk)
        # the step loop alone, from the same start, for 5 s
        plain = sjt.SJTSolver(robot, acceleration_limits=acceleration, jerk_limits=jerk)
        q = q0.copy()
        for _ in range(5000):
            q = plain.step(q, target)
        stuck += pose_error(robot, q, target)[0] > 1e-3
    assert stuck >= 1  # (these pairs include starts the step loop does not bring there)


def test_move_to_refuses_what_it_cannot_do(ur5):
    solver = sjt.SJTSolver(ur5)
    far = pin.SE3(np.eye(3), np.array([3.0, 0.0, 0.0]))  # beyond the arm's reach
    with pytest.raises(ValueError, match="solve\\(\\) found no configuration"):
        solver.move_to(ur5.q0, far, budget=200)
    with pytest.raises(ValueError, match="share"):
        solver.move_to(ur5.q0, ur5.fk(ur5.q0), share=1.5)
    with pytest.raises(ValueError, match="q must"):
        solver.move_to(None, ur5.fk(ur5.q0))
