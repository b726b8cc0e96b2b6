"""solve() on one pose task in one compiled call per start (kernels.search_pose): the same
search as the Python loop over the task stack, its pose error Pinocchio's log6, its restarts
the numbers of numpy's generators."""

import math

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin.bench.ik import problems

from .test_constraints import JointBand


def _pair(robot, method="sjt"):
    """A solver on the one-call path and one made to take the Python loop, with the model of
    the one-call path: the pose task's rows J (the Python loop's own model is the exact
    derivative of log6, ``Jlog6 J``; see test_solve's floating base)."""
    fast, loop = sjt.make_solver(method, robot), sjt.make_solver(method, robot)
    assert fast.search().pose is not None
    search = loop.search()
    search.pose = None
    search.stack.task.error_jacobian = lambda J: J
    return fast, loop


@pytest.mark.filterwarnings("ignore:kinova. the reference configuration")
@pytest.mark.parametrize("name", ["ur5", "panda", "kinova"])  # Kinova: continuous joints
def test_one_call_per_start_is_the_python_loop(name):
    """Same accepted trials, stalls and restarts as the loop over stack.evaluate,
    SetPointSearch.iterate and pin.integrate: the same q to rounding (the error in world axes)."""
    robot = sjt.Robot.from_example(name)
    fast, loop = _pair(robot)
    for target, seed in problems(robot, 15, seed=21):
        a, b = fast.solve(target, seed), loop.solve(target, seed)
        assert (a.success, a.iterations, a.restarts) == (b.success, b.iterations, b.restarts)
        np.testing.assert_allclose(a.q, b.q, rtol=0, atol=1e-9)
        assert abs(a.error - b.error) < 1e-12
    dls_fast, dls_loop = _pair(robot, "dls")
    target, seed = problems(robot, 1, seed=22)[0]
    np.testing.assert_allclose(dls_fast.solve(target, seed).q, dls_loop.solve(target, seed).q,
                               rtol=0, atol=1e-9)


@pytest.mark.parametrize("angle", [0.0, 1e-9, 1e-4, 0.7, 2.0, 2.5, np.pi - 1e-3,
                                   np.pi - 1e-8])
def test_pose_error_is_log6_in_world_axes(ur5, angle):
    """The kernel's error of its first iteration: blockdiag(R, R) log6(oMf^-1 oMd), also at
    rotations near 0 and pi."""
    solver = sjt.SJTSolver(ur5)
    search = solver.search()
    rng = np.random.default_rng(int(angle * 1e3))
    q = ur5.random_configuration(rng)
    here = ur5.fk(q)
    axis = rng.normal(size=3)
    offset = pin.SE3(pin.exp3(angle * axis / np.linalg.norm(axis)), rng.normal(size=3) * 0.3)
    target = here * offset
    search.aim([target], 1e-6)
    converged, used = search.run(q, 1, math.inf)  # one iteration: the error at q
    assert used == 1 and not converged
    loop = search.pose
    expected = pin.log6(here.actInv(target)).vector
    R = here.rotation
    np.testing.assert_allclose(loop.e, np.concatenate([R @ expected[:3], R @ expected[3:]]),
                               rtol=0, atol=1e-9 if angle > 3.1 else 1e-12)


def test_restarts_draw_what_numpy_draws(panda):
    """A restart's q is numpy's uniform within the limits, bitwise; an int seed gives what a
    new default_rng(seed) gives, also after another seed and after a Generator."""
    search = sjt.SJTSolver(panda).search()
    seed_q = panda.q0.copy()
    limited = np.isfinite(panda.lower_limits)  # every coordinate of Panda's
    for seed in (3, 4, 3):
        a = search.random(seed_q, search.generator(seed))
        expected = seed_q.copy()
        expected[limited] = np.random.default_rng(seed).uniform(panda.lower_limits[limited],
                                                                panda.upper_limits[limited])
        np.testing.assert_array_equal(a, expected)
    solver = sjt.SJTSolver(panda)
    pairs = problems(panda, 6, seed=23)
    first = [solver.solve(t, s, rng=7) for t, s in pairs]
    solver.solve(*pairs[0], rng=np.random.default_rng(8))
    again = [solver.solve(t, s, rng=7) for t, s in pairs]
    fresh = [sjt.SJTSolver(panda).solve(t, s, rng=np.random.default_rng(7)) for t, s in pairs]
    assert any(r.restarts for r in first)  # restarts were made (the table's first)
    for a, b, c in zip(first, again, fresh, strict=True):
        np.testing.assert_array_equal(a.q, b.q)
        np.testing.assert_array_equal(a.q, c.q)


def test_a_pose_task_with_user_limits_keeps_them(ur5):
    """User limits take the loop that enforces them at every iteration: the pose task's
    solutions keep the elbow in its band."""
    solver = sjt.SJTSolver(ur5, limits=[JointBand(ur5, "elbow_joint", 0.5, 1.6)])
    assert solver.search().pose is None
    rng = np.random.default_rng(24)
    for _ in range(5):
        q_goal = ur5.random_configuration(rng)
        q_goal[2] = rng.uniform(0.6, 1.45)
        result = solver.solve(ur5.fk(q_goal), q_goal + 0.1)
        assert result.success
        assert 0.5 - 1e-9 <= result.q[2] <= 1.6 + 1e-9


def test_other_task_stacks_take_the_python_loop(ur5):
    """A position task, a weighted pose task with unequal rows and two tasks are no single
    pose task in world axes: the loop over the stack serves them."""
    unequal = sjt.PoseTask(weight=[1.0, 2.0, 1.0, 1.0, 1.0, 1.0])
    for solver in (sjt.SJTSolver(ur5, task=sjt.PositionTask()), sjt.SJTSolver(ur5, task=unequal),
                   sjt.SJTSolver(ur5, posture=sjt.PostureTask(weight=1e-3))):
        assert solver.search().pose is None
    equal = sjt.SJTSolver(ur5, task=sjt.PoseTask(weight=[2.0, 2.0, 2.0, 1.0, 1.0, 1.0]))
    assert equal.search().pose is not None


def _iterations_until_stop(errors, quick):
    """SetPointSearch.iterate fed the error vectors ``errors`` in turn (J fixed, no limits):
    the iterations until it returns a status other than CONTINUE (None: it never did)."""
    from sjt_pin import ik
    from sjt_pin import kernels as K

    none = np.zeros(0, dtype=np.int64)
    search = K.SetPointSearch(np.ones(6), np.ones(6), 6, none, none, np.zeros(0), np.zeros(0),
                              damping=ik.MU, column_tol=0.0)
    search.tol, search.max_step, search.error_rows = 1e-6, ik.MAX_STEP, 6
    search.nu_start, search.stale_iters, search.progress = ik.NU_START, ik.STALE_ITERS, ik.PROGRESS
    search.held_iters, search.held_progress = ik.HELD_ITERS, ik.HELD_PROGRESS
    search.start(quick)
    J, q = np.eye(6), np.zeros(6)
    for k, e in enumerate(errors, 1):
        if search.iterate(J, e, q):
            return k
    return None


def test_the_quick_stall_test_waits_for_a_rejected_step():
    """The quick test (halve within HELD_ITERS) stops a start whose steps are rejected (its
    error does not fall: it is in a local minimum) after HELD_ITERS rejections, sooner than the
    patient test, and only with the quick test on; a start whose every step is accepted, its
    error falling by 5 % an iteration (the damping of its first iterations holding it back),
    runs on."""
    from sjt_pin import ik

    stuck = [np.full(6, 0.1)] * 20  # every trial no better than the first: rejected
    assert _iterations_until_stop(stuck, True) == 1 + ik.HELD_ITERS
    assert _iterations_until_stop(stuck, False) == 1 + ik.STALE_ITERS
    assert ik.HELD_ITERS < ik.STALE_ITERS
    slow = [np.full(6, 0.1 * 0.95**k) for k in range(20)]  # accepted, 5 % better each time
    assert _iterations_until_stop(slow, True) is None
