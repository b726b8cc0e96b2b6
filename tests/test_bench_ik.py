"""``sjt-pin bench ik`` on a few poses: the rows, the table, the check and the peers' joint
values (Kinova's continuous joints)."""


import numpy as np
import pytest

import sjt_pin as sjt
from sjt_pin.bench import ik


@pytest.fixture(scope="module")
def kinova() -> sjt.Robot:
    return sjt.Robot.from_example("kinova")


def test_benchmark_rows_and_table():
    rows = ik.ik_benchmark(robots=("ur5", "kinova"), poses=5)
    labels = {"SJT", "SJT, timeout=5 ms", "DLS"}
    assert {r.method for r in rows} >= labels
    for r in rows:
        assert r.poses == 5 and 0.0 <= r.success <= 1.0
        assert 0.0 < r.median_ms <= r.p90_ms <= r.p99_ms
        if r.method in labels:
            assert r.iterations_median >= 1 and r.restarts_mean >= 0
    table = ik.ik_table(rows).splitlines()
    assert len(table) == 2 + len(rows) and table[2].startswith("| ur5 | SJT | 5 |")


def test_solved_accepts_a_solution_and_rejects_one_outside_the_limits(ur5):
    q = ur5.random_configuration(np.random.default_rng(0))
    target = ur5.fk(q)
    assert ik.solved(ur5, q, target)
    assert not ik.solved(ur5, None, target)
    elbow = 2  # limits +-pi: the same pose a turn away is outside them
    outside = q.copy()
    outside[elbow] += 2 * np.pi if q[elbow] < 0 else -2 * np.pi
    assert ur5.fk(outside).isApprox(target, 1e-9)
    assert not ik.solved(ur5, outside, target)


def test_solved_with_continuous_joints(kinova):
    q = kinova.random_configuration(np.random.default_rng(1))
    target = kinova.fk(q)
    assert ik.solved(kinova, q, target)  # continuous joints: infinite limits
    chain = ik.Chain(kinova)
    stretched = q.copy()
    stretched[chain.index[chain.circle]] *= 2  # not a unit (cos, sin)
    assert not ik.solved(kinova, stretched, target)


def test_chain_values_round_trip(kinova):
    chain = ik.Chain(kinova)
    assert len(chain) == 6 and chain.circle.sum() == 3
    rng = np.random.default_rng(2)
    q, seed = kinova.random_configuration(rng), kinova.random_configuration(rng)
    np.testing.assert_allclose(chain.configuration(chain.values(q), seed), q, atol=1e-12)
    values = rng.uniform(chain.lower.clip(-np.pi), chain.upper.clip(max=np.pi))
    np.testing.assert_allclose(chain.values(chain.configuration(values, seed)), values,
                               atol=1e-12)


@pytest.mark.bench  # needs pytracik, from the bench extra: pytest -m bench
def test_tracik_sees_the_same_kinova(kinova):
    import pytracik

    chain = ik.Chain(kinova)
    solver = ik.tracik_solver(kinova, chain)
    assert pytracik.get_num_joints(solver) == len(chain)
    q = kinova.random_configuration(np.random.default_rng(3))
    np.testing.assert_allclose(pytracik.fk(solver, chain.values(q)), kinova.fk(q).homogeneous,
                               atol=1e-12)
    run = ik._tracik(kinova)
    found = [ik.solved(kinova, run(target, seed).q, target)
             for target, seed in ik.problems(kinova, 5)]
    assert sum(found) >= 4  # its eps, 1e-5 per component, may miss 1e-5 m in norm


def test_solve_many_throughput_row():
    row = ik.many_throughput("ur5", poses=300)
    assert row.poses == 300 and row.processes == 2 and row.identical
    assert row.single > 0 and row.parallel > 0 and row.speedup == row.parallel / row.single
    assert row.dask > 0 and row.dask_ratio == row.dask / row.parallel
    line = ik.many_line(row)
    assert "in the pool of 2" in line and "on Dask" in line and line.endswith("yes")


@pytest.mark.bench  # needs roboticstoolbox-python, from the bench extra: pytest -m bench
def test_rtb_solves_a_sub_chain_of_a_larger_robot():
    """Baxter's right arm is joints 1..7 of a 19-joint robot: robotics-toolbox's runner numbers
    the chain's joints as its own (it solved 0 % when it kept the robot's numbering)."""
    robot = sjt.Robot.from_example("baxter", ee_frame=ik.EE_FRAMES["baxter"])
    run = ik._rtb(robot)
    pairs = ik.problems(robot, 20)
    solved = sum(ik.solved(robot, run(target, seed).q, target) for target, seed in pairs)
    assert solved >= 19


def test_solve_succeeds_on_random_robots_with_every_method():
    """The seeded random robots of bench ik (chains and trees, every joint type): solve() with
    its defaults solves at least 99.5 % of reachable poses with every method."""
    from sjt_pin.bench.random_robots import random_robots, random_table

    rows = random_robots(count=60, poses=4)
    assert all(row.robots >= 50 for row in rows), random_table(rows)
    assert all(row.success >= 0.995 for row in rows), random_table(rows)
