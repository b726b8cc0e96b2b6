"""solve()'s restarts (sjt_pin.restarts): the seeded table of starts nearest the target, in the
order of the task's own weighted pose distance, the same in every solver and process."""

import pickle

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin.bench.ik import problems, solved
from sjt_pin.ik import NEAREST
from sjt_pin.restarts import NearStarts, Sampler


def _distance(robot, frame_id, q, target, w_p, w_r):
    """w_p^2 |p - p_t|^2 + w_r^2 (2 sin(theta / 2))^2 of the frame at q, from Pinocchio."""
    pose = robot.fk(q, frame_id)
    theta = np.linalg.norm(pin.log3(pose.rotation.T @ target.rotation))
    return (w_p**2 * np.sum((pose.translation - target.translation) ** 2)
            + w_r**2 * (2.0 * np.sin(theta / 2.0)) ** 2)


def test_the_table_gives_its_configurations_nearest_first(panda):
    """next() walks the table in the order of the pose distance computed from Pinocchio's
    forward kinematics and log3, every configuration within the limits."""
    search = sjt.SJTSolver(panda).search()
    w = search.stack.sqrt_weight
    table = NearStarts(panda, panda.ee_frame_id, Sampler(panda), w[0], w[3], 300, 1)
    target = panda.fk(panda.random_configuration(np.random.default_rng(4)))
    table.aim(target.homogeneous)
    given = [table.next() for _ in range(300)]
    distances = [_distance(panda, panda.ee_frame_id, q, target, w[0], w[3]) for q in given]
    assert np.all(np.diff(distances) >= -1e-9)
    assert all(np.all(q >= panda.lower_limits) and np.all(q <= panda.upper_limits)
               for q in given)
    table.aim(target.homogeneous)  # aim again: from the nearest again
    np.testing.assert_array_equal(table.next(), given[0])


def test_the_table_is_the_same_in_every_solver_and_copy(panda):
    """A fresh solver and a pickled one (another process's) restart from the same table:
    solve() gives the same q for the same inputs, bitwise."""
    solver = sjt.SJTSolver(panda)
    copy = pickle.loads(pickle.dumps(solver))
    pairs = problems(panda, 12, seed=5)
    first = [solver.solve(t, s) for t, s in pairs]
    assert any(r.restarts for r in first)  # the table was used
    for r, (t, s) in zip(first, pairs, strict=True):
        np.testing.assert_array_equal(copy.solve(t, s).q, r.q)
        np.testing.assert_array_equal(sjt.SJTSolver(panda).solve(t, s).q, r.q)


def test_past_the_table_the_restarts_follow_the_seed(ur5):
    """Out of reach, every start stalls: after the table's NEAREST starts the random ones come
    from rng, so a seed repeats its search exactly and another seed makes other starts (each
    ends at the same best q, the arm stretched towards the target, after other restarts)."""
    solver = sjt.SJTSolver(ur5)
    far = pin.SE3(np.eye(3), np.array([0.0, 0.0, 3.0]))  # 3 m up: beyond UR5's 1 m
    a, b, c = (solver.solve(far, ur5.q0, rng=seed, budget=400) for seed in (1, 1, 2))
    assert not a.success and a.restarts > NEAREST
    np.testing.assert_array_equal(a.q, b.q)
    assert (a.restarts, a.error) == (b.restarts, b.error)
    assert (a.restarts, a.error) != (c.restarts, c.error)


def test_no_table_where_a_restart_cannot_use_it(ur5):
    """Only a single pose task has a table: a position task restarts at random."""
    solver = sjt.SJTSolver(ur5, task=sjt.PositionTask())
    assert NearStarts.of(ur5, solver.search().stack, Sampler(ur5)) is None
    target = ur5.fk(ur5.random_configuration(np.random.default_rng(6))).translation
    result = solver.solve(target, ur5.q0)
    assert result.success


@pytest.mark.parametrize("name", ["panda", "ur5"])
def test_solve_still_solves_every_pose(name):
    """With the table's restarts, solve() with its defaults solves every one of 200 random
    reachable poses (checked by the benchmark's own test, not the solver's claim)."""
    robot = sjt.Robot.from_example(name)
    solver = sjt.SJTSolver(robot)
    pairs = problems(robot, 200, seed=8)
    assert all(solved(robot, solver.solve(t, s).q, t) for t, s in pairs)


@pytest.mark.parametrize("name", ["panda", "ur5"])
def test_the_table_s_starts_in_one_call_are_those_of_one_call_each(name):
    """Without a timeout the table's restarts run in one compiled call; with one (the clock
    read between starts), one call each: the same starts, iterations, restarts, error and q,
    bitwise, on poses that restart."""
    robot = sjt.Robot.from_example(name)
    solver = sjt.SJTSolver(robot)
    restarted = 0
    for t, s in problems(robot, 60, seed=9):
        a, b = solver.solve(t, s), solver.solve(t, s, timeout=1e9)
        assert (a.iterations, a.restarts, a.error, a.success) == (b.iterations, b.restarts,
                                                                  b.error, b.success)
        np.testing.assert_array_equal(a.q, b.q)
        restarted += a.restarts > 0
    assert restarted >= 5
    far = pin.SE3(np.eye(3), np.array([0.0, 0.0, 3.0]))  # out of reach: every start fails
    a, b = solver.solve(far, robot.q0, budget=300), solver.solve(far, robot.q0, budget=300,
                                                                timeout=1e9)
    assert (a.iterations, a.restarts, a.error) == (b.iterations, b.restarts, b.error)
    np.testing.assert_array_equal(a.q, b.q)
    c = solver.solve(far, robot.q0, restarts=3)  # fewer restarts than the table has
    assert c.restarts == 3 and not c.success


def test_a_table_that_does_not_fit_the_robot_is_refused(panda):
    """search_table with a table whose configurations are not the robot's q (or a distance of
    another length) raises ValueError instead of reading past them."""
    from sjt_pin.kernels import search_table

    solver = sjt.SJTSolver(panda)
    search = solver.search()
    search.aim([panda.fk(panda.q0)], 1e-6)
    call = search.pose.call
    for configurations, distance in ((np.zeros((5, panda.nq - 1)), np.zeros(5)),
                                     (np.zeros((5, panda.nq)), np.zeros(4))):
        with pytest.raises(ValueError, match="table's arrays do not fit"):
            search_table(*call, 10, configurations, distance, np.zeros(panda.nq), 1, 10, np.inf)


def test_many_starts_are_those_of_one_call_each(ur5, continuous_wrist):
    """Sampler.many (the table's starts in one draw) gives bitwise the starts of as many calls
    in turn: limited joints, a continuous joint's (cos, sin), and an unlimited revolute joint
    (UR5's last joint taken as one)."""
    turning = Sampler(ur5)
    turning.limited, turning.turning = turning.limited[:5], turning.limited[5:]
    turning.lower, turning.upper = turning.lower[:5], turning.upper[:5]
    turning.span = turning.upper - turning.lower
    for robot, sampler in ((ur5, Sampler(ur5)), (continuous_wrist, Sampler(continuous_wrist)),
                           (ur5, turning)):
        seed = robot.random_configuration(np.random.default_rng(3))
        one = [sampler(seed, rng) for rng in [np.random.default_rng(4)] for _ in range(40)]
        many = sampler.many(seed, np.random.default_rng(4), 40)
        np.testing.assert_array_equal(many, np.array(one))
    assert Sampler(continuous_wrist).circle.size and turning.turning.size
