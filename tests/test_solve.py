"""solve(): set-point IK to random reachable poses, within limits, with restarts."""

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt


@pytest.mark.parametrize("method", ["sjt", "dls"])
@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_random_reachable_poses(name, method):
    robot = sjt.Robot.from_example(name)
    rng = np.random.default_rng(7)
    solver = sjt.make_solver(method, robot)
    results = []
    for _ in range(30):
        target = robot.fk(robot.random_configuration(rng))
        result = solver.solve(target, robot.random_configuration(rng), tol=1e-5, restarts=20,
                              rng=rng)
        results.append(result)
        if result.success:
            error = pin.log6(robot.fk(result.q).actInv(target)).vector
            assert np.linalg.norm(error) < 1e-5
        assert np.all(result.q >= robot.lower_limits - 1e-12)
        assert np.all(result.q <= robot.upper_limits + 1e-12)
    assert np.mean([r.success for r in results]) >= 29 / 30


def test_sjt_direction_alone_converges_from_nearby(ur5):
    q_goal = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])
    target = ur5.fk(q_goal)
    result = sjt.SJTSolver(ur5).solve(target, q_goal + 0.1, tol=1e-6, inner=1, max_iters=5000)
    assert result.success and result.error < 1e-6 and result.iterations > 1


def test_unreachable_pose_fails_cleanly(ur5):
    target = pin.SE3(np.eye(3), np.array([2.0, 0.0, 0.5]))
    result = sjt.SJTSolver(ur5).solve(target, ur5.q0, tol=1e-6, restarts=2)
    assert not result.success and np.isfinite(result.error) and result.error > 0.5
    assert np.all(np.isfinite(result.q)) and result.restarts == 2


def test_solve_arguments(ur5):
    solver = sjt.SJTSolver(ur5)
    with pytest.raises(ValueError, match="tol must be a positive number"):
        solver.solve(ur5.fk(ur5.q0), ur5.q0, tol=0)
    with pytest.raises(ValueError, match=r"q0 must have shape \(6,\)"):
        solver.solve(ur5.fk(ur5.q0), np.zeros(2))
    with pytest.raises(ValueError, match="inner must be >= 1"):
        solver.solve(ur5.fk(ur5.q0), ur5.q0, inner=0)
