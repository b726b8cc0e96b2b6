"""``sjt-pin bench settle`` on a few draws: the runs come to rest within every limit they were
given, the draws are reproducible, and a continuous joint's finite differences keep their
digits."""

import numpy as np
import pinocchio as pin
import pytest

import sjt_pin as sjt
from sjt_pin.bench import settle


@pytest.fixture(scope="module")
def rows():
    return settle.settle(seeds=3, arms=("ur3_limited", "kinova"), methods=("sjt", "jp"))


def test_each_scene_comes_to_rest_within_its_limits(rows):
    assert len(rows) == 3 * 2 * 2
    assert {r.scene for r in rows} == set(settle.SCENES)
    for r in rows:
        assert r.state == "rest", r
        assert r.ratio_v <= 1.0 + 1e-6, r
        assert np.isnan(r.ratio_a) != r.acceleration and np.isnan(r.ratio_j) != r.jerk
        assert not r.ratio_a > 1.01 and not r.ratio_j > 1.01, r
        assert 0.0 < r.rest_s <= r.seconds <= settle.LONGEST
        if r.scene == "beyond":  # past the farthest reach: the error stays above 0.1 m
            assert not r.reachable and r.error > 0.1 and r.reach_s is None
        if r.reach_s is not None:
            assert r.reachable and r.error < settle.REACHED
    table = settle.settle_table(rows).splitlines()
    assert len(table) == 2 + 3 and table[-1].startswith("| all | 12 | 12 | 0 | 0 | 0 |")


def test_the_draws_are_reproducible(rows):
    again = settle.settle(seeds=1, arms=("kinova",), methods=("sjt",))
    assert again == [r for r in rows if r.robot == "kinova" and r.seed == 0
                     and r.method == "sjt"]


def test_joint_angles_unwrap_a_continuous_joint():
    robot = sjt.Robot.from_example("kinova")  # continuous joints: (cos, sin) in q
    model = robot.model
    rng = np.random.default_rng(1)
    v = rng.uniform(-1.0, 1.0, model.nv)
    qs = np.array([pin.integrate(model, robot.q0, k * 0.37 * v) for k in range(30)])
    angles = settle.joint_angles(model, qs)
    assert np.allclose(np.diff(angles, axis=0), 0.37 * v, atol=1e-12)
    with pytest.raises(ValueError, match="1-dof"):
        settle.joint_angles(sjt.Robot.from_example("solo12").model, np.zeros((2, 19)))
