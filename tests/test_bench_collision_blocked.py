"""``sjt-pin bench collision``'s blocked targets (:mod:`sjt_pin.bench.collision_blocked`): one
run of the table, its fields measured, not copied."""

import numpy as np

import sjt_pin as sjt
from sjt_pin.bench import collision_blocked as blocked


def test_a_blocked_run_rests_within_the_margin_and_the_limits():
    rows = blocked.blocked(arms=("ur5_gripper",), seeds=(1,), methods=("sjt",),
                           jerks=(blocked.JERK,))
    (row,) = rows
    assert (row.robot, row.seed, row.method, row.jerk) == ("ur5_gripper", 1, "SJT", blocked.JERK)
    assert 0.0 < row.rest_at < blocked.SECONDS and row.rest == 0.0
    assert row.min_distance >= blocked.MARGIN - 1e-3
    assert row.acceleration <= 1.01 and row.jerk_ratio <= 1.01 and row.yielded == 0
    table = blocked.blocked_table(rows).splitlines()
    assert len(table) == 3 and table[2].startswith("| ur5_gripper | 1 | SJT | 7500 |")


def test_the_scene_is_reproducible_and_clear_of_the_robot_at_the_start():
    robot = sjt.Robot.from_example("ur5_gripper")
    a = blocked.blocked_scene(robot, np.random.default_rng(3))
    b = blocked.blocked_scene(robot, np.random.default_rng(3))
    np.testing.assert_array_equal(a[0], b[0])
    assert a[1].isApprox(b[1])
    limit = sjt.CollisionLimit(robot, [a[3]], self_collision=True)
    assert min(d.distance for d in limit.distances(a[0])) >= 0.02
    pose, _ = a[2](1.0)  # (the line ends at the end pose after 1 s)
    assert pose.isApprox(a[1])
