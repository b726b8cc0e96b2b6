"""solve(): set-point IK to random reachable poses with its defaults, within limits, with
restarts; solve_many."""

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin.bench.ik import problems, solved


def check(robot, result, target, tol=1e-6):
    """The solution within the limits and on the target (independently of the solver)."""
    assert np.all(result.q >= robot.lower_limits) and np.all(result.q <= robot.upper_limits)
    if result.success:
        error = pin.log6(robot.fk(result.q).actInv(target)).vector
        assert np.linalg.norm(error) < tol
        assert result.error < tol


@pytest.mark.filterwarnings("ignore:kinova. the reference configuration")
@pytest.mark.parametrize("name", ["ur5", "panda", "kinova", "xarm7"])
@pytest.mark.parametrize("method", ["sjt", "dls"])
def test_defaults_solve_random_reachable_poses(name, method):
    """TRAC-IK's protocol: targets and seeds random within the limits; the defaults, with the
    wall-clock budget off so that the test does not depend on the machine."""
    robot = sjt.Robot.from_example(name)
    solver = sjt.make_solver(method, robot)
    pairs = problems(robot, 40, seed=3)
    results = [solver.solve(target, seed, timeout=None) for target, seed in pairs]
    for (target, _), result in zip(pairs, results, strict=True):
        check(robot, result, target)
        assert solved(robot, result.q, target) == result.success
    assert sum(r.success for r in results) >= 39


def test_first_start_is_the_seed_and_converges_from_nearby(ur5):
    q_goal = np.array([0.3, -1.2, 1.5, -1.8, -1.5, 0.2])
    target = ur5.fk(q_goal)
    result = sjt.SJTSolver(ur5).solve(target, q_goal + 0.1, restarts=0)
    assert result.success and result.restarts == 0
    assert 1 < result.iterations < 20  # Levenberg-Marquardt: a few iterations near a solution
    check(ur5, result, target)


def test_unreachable_pose_fails_cleanly_within_its_budget(ur5):
    target = pin.SE3(np.eye(3), np.array([2.0, 0.0, 0.5]))
    result = sjt.SJTSolver(ur5).solve(target, ur5.q0, timeout=None, budget=300)
    assert not result.success and np.isfinite(result.error) and result.error > 0.5
    assert result.iterations <= 300 and result.restarts >= 1
    check(ur5, result, target)
    few = sjt.SJTSolver(ur5).solve(target, ur5.q0, restarts=2, timeout=None)
    assert few.restarts == 2


def test_results_repeat_for_a_seed(panda):
    solver = sjt.SJTSolver(panda)
    target, seed = problems(panda, 1, seed=11)[0]
    a = solver.solve(target, seed, rng=5, timeout=None)
    b = solver.solve(target, seed, rng=np.random.default_rng(5), timeout=None)
    np.testing.assert_array_equal(a.q, b.q)
    assert (a.iterations, a.restarts) == (b.iterations, b.restarts)


def test_bad_targets_raise_as_step_does(ur5):
    solver = sjt.SJTSolver(ur5)
    nan = pin.SE3(np.eye(3), np.array([np.nan, 0.0, 0.0]))
    for target in (nan, np.full((4, 4), np.nan)):
        with pytest.raises(ValueError, match="NaN"):
            solver.solve(target, ur5.q0)
        with pytest.raises(ValueError, match="NaN"):
            solver.step(ur5.q0, target)
    scaled = ur5.fk(ur5.q0)
    scaled.rotation = 1.1 * scaled.rotation
    with pytest.raises(ValueError, match="not a rotation"):
        solver.solve(scaled, ur5.q0)
    far = ur5.fk(ur5.q0) * pin.SE3(np.eye(3), np.array([1e200, 0.0, 0.0]))
    for solve_or_step in (lambda t: solver.solve(t, ur5.q0), lambda t: solver.step(ur5.q0, t)):
        with pytest.raises(ValueError, match="too far"):
            solve_or_step(far)
    position = sjt.SJTSolver(ur5, task=sjt.PositionTask())
    with pytest.raises(ValueError, match="NaN"):
        position.solve([np.nan, 0.0, 0.0], ur5.q0)


def test_solve_arguments(ur5):
    solver = sjt.SJTSolver(ur5)
    target = ur5.fk(ur5.q0)
    with pytest.raises(ValueError, match="tol must be a positive number"):
        solver.solve(target, ur5.q0, tol=0)
    with pytest.raises(ValueError, match=r"q0 must have shape \(6,\)"):
        solver.solve(target, np.zeros(2))
    with pytest.raises(ValueError, match="max_iters must be an integer >= 1"):
        solver.solve(target, ur5.q0, max_iters=0)
    with pytest.raises(ValueError, match="restarts must be an integer >= 0"):
        solver.solve(target, ur5.q0, restarts=-1)
    with pytest.raises(TypeError, match="max_iters must be an integer"):
        solver.solve(target, ur5.q0, max_iters=None)
    with pytest.raises(TypeError, match="restarts must be an integer"):
        solver.solve(target, ur5.q0, restarts="3")
    with pytest.raises(ValueError, match="timeout must be a positive number"):
        solver.solve(target, ur5.q0, timeout=-1.0)


def test_full_turn_joints_wrap_instead_of_stopping_at_a_limit(ur5):
    """UR5's base joint turns +-2 pi: from a seed near -2 pi, the target's angle is reached by
    turning the other way round, not blocked at the limit."""
    q_goal = np.array([3.0, -1.2, 1.5, -1.8, -1.5, 0.2])
    target = ur5.fk(q_goal)
    seed = q_goal.copy()
    seed[0] = -6.2
    result = sjt.SJTSolver(ur5).solve(target, seed, restarts=0, timeout=None)
    assert result.success
    check(ur5, result, target)


def test_floating_base_is_free_and_reported_unbounded():
    talos = sjt.Robot.from_example("talos_arm")
    solver = sjt.SJTSolver(talos, task=sjt.PoseTask())
    target = talos.fk(talos.random_configuration(np.random.default_rng(2)))
    result = solver.solve(target, talos.q0, timeout=None)
    assert result.success
    check(talos, result, target)
    humanoid = sjt.Robot.from_example("talos")
    base = slice(0, 7)  # the free flyer: no limits, reported as such
    assert np.all(np.isinf(humanoid.lower_limits[base]))
    assert np.all(np.isinf(humanoid.upper_limits[base]))
    hand = sjt.SJTSolver(humanoid, task=sjt.PoseTask(frame="gripper_left_joint"))
    step = pin.SE3(np.eye(3), np.array([0.05, 0.0, 0.0]))
    goal = hand.robot.fk(humanoid.q0, "gripper_left_joint") * step
    result = hand.solve(goal, humanoid.q0, timeout=None)
    assert result.success
    check(humanoid, result, goal)


def _anywhere(robot, rng, reach=3.0):
    """A random q with the free flyer anywhere within ``reach`` (m) of the origin, any turn."""
    q = robot.random_configuration(rng)
    q[:3] = rng.uniform(-reach, reach, 3)
    quaternion = rng.normal(size=4)
    q[3:7] = quaternion / np.linalg.norm(quaternion)
    return q


@pytest.mark.filterwarnings("ignore:target is .* the robot's base")  # metres away: meant
@pytest.mark.parametrize("method", ["sjt", "jt", "dls", "jp"])
def test_a_floating_base_far_from_its_target_is_solved(method):
    """SO-100's arm on a free flyer (nq 13), targets with the base metres and any turn away:
    the search's model is the exact derivative of log6 (Jlog6 J), so its steps go downhill
    however far the target; with the CLIK rows alone SJT's steps turned the base the wrong
    way and every start stalled at |e| ~ 1-8."""
    robot = sjt.Robot.from_example("so100", ee_frame="jaw")
    solver = sjt.make_solver(method, robot)
    rng = np.random.default_rng(1)
    for k in range(16):
        target = robot.fk(_anywhere(robot, rng))
        result = solver.solve(target, _anywhere(robot, rng), rng=k)
        assert result.success, (k, result.error)
        check(robot, result, target)


def test_solve_many_equals_the_sequential_solves(ur5):
    solver = sjt.SJTSolver(ur5)
    pairs = problems(ur5, 12, seed=4)
    targets = [t for t, _ in pairs]
    seeds = np.array([s for _, s in pairs])
    parallel = sjt.solve_many(solver, targets, seeds, processes=2, chunk=4, progress=False,
                              timeout=None)
    sequential = sjt.solve_many(solver, targets, seeds, processes=1, progress=False,
                                timeout=None)
    by_hand = [solver.solve(t, s, rng=np.random.default_rng([0, k]), timeout=None)
               for k, (t, s) in enumerate(pairs)]
    for a, b, c in zip(parallel, sequential, by_hand, strict=True):
        np.testing.assert_array_equal(a.q, b.q)
        np.testing.assert_array_equal(a.q, c.q)
        assert a.success == b.success == c.success
    assert all(r.success for r in parallel)


def test_solve_many_takes_any_executor(ur5):
    from concurrent.futures import ThreadPoolExecutor

    solver = sjt.SJTSolver(ur5)
    pairs = problems(ur5, 6, seed=5)
    with ThreadPoolExecutor(2) as executor:
        results = sjt.solve_many(solver, [t for t, _ in pairs], ur5.q0, executor=executor,
                                 chunk=2, progress=False, timeout=None)
    reference = sjt.solve_many(solver, [t for t, _ in pairs], ur5.q0, processes=1,
                               progress=False, timeout=None)
    for a, b in zip(results, reference, strict=True):
        np.testing.assert_array_equal(a.q, b.q)


def test_solve_many_in_parts_equals_one_call(ur5):
    """``first=`` numbers a part of a larger batch: parts solved apart (as on a cluster) give
    what one call gives."""
    solver = sjt.SJTSolver(ur5)
    pairs = problems(ur5, 8, seed=6)
    targets, seeds = [t for t, _ in pairs], np.array([s for _, s in pairs])
    whole = sjt.solve_many(solver, targets, seeds, processes=1, progress=False, timeout=None)
    parts = (sjt.solve_many(solver, targets[:5], seeds[:5], processes=1, progress=False,
                            timeout=None)
             + sjt.solve_many(solver, targets[5:], seeds[5:], processes=1, progress=False,
                              timeout=None, first=5))
    for a, b in zip(whole, parts, strict=True):
        np.testing.assert_array_equal(a.q, b.q)
        assert a.iterations == b.iterations


def test_solve_many_in_two_threads_with_their_own_solvers(ur5):
    """Solving in this process keeps no module state: two threads, each with its own solver,
    get what each gets alone."""
    from concurrent.futures import ThreadPoolExecutor

    pairs = problems(ur5, 12, seed=7)
    batches = [[t for t, _ in pairs[:6]], [t for t, _ in pairs[6:]]]

    def run(targets):
        return sjt.solve_many(sjt.SJTSolver(ur5), targets, ur5.q0, processes=1, chunk=2,
                              progress=False, timeout=None)

    alone = [run(b) for b in batches]
    with ThreadPoolExecutor(2) as pool:
        together = list(pool.map(run, batches))
    for a, b in zip(sum(alone, []), sum(together, []), strict=True):
        np.testing.assert_array_equal(a.q, b.q)


def test_solve_many_arguments(ur5):
    solver, target = sjt.SJTSolver(ur5), ur5.fk(ur5.q0)
    assert sjt.solve_many(solver, [], ur5.q0, progress=False) == []
    for name, value, error in [("chunk", 0, ValueError), ("processes", 0, ValueError),
                               ("seed", None, TypeError), ("first", -1, ValueError),
                               ("inflight", 0, ValueError)]:
        with pytest.raises(error, match=f"{name} must be an integer"):
            sjt.solve_many(solver, [target], ur5.q0, progress=False, **{name: value})
    with pytest.raises(ValueError, match="q0 must be real"):
        sjt.solve_many(solver, [target], np.array([ur5.q0 + 0j]), progress=False)
    with pytest.raises(ValueError, match="q0 contains NaN"):
        sjt.solve_many(solver, [target], np.full((1, 6), np.nan), progress=False)
    with pytest.raises(ValueError, match=r"q0 must have shape \(6,\) or \(2, 6\)"):
        sjt.solve_many(solver, [target] * 2, np.zeros((3, 6)), progress=False)
    with pytest.raises(TypeError, match="rng is not an option of solve_many"):
        sjt.solve_many(solver, [target], ur5.q0, progress=False, rng=1)
    with pytest.raises(TypeError, match="executor must be a concurrent.futures.Executor"):
        sjt.solve_many(solver, [target], ur5.q0, progress=False, executor=object())

