"""``sjt-pin bench reach`` on a few pairs: every limit kept on every run, ``move_to`` reaching
each target ``solve()`` finds, the jerk grid settling within its limits, and the tables."""

import math

import numpy as np
import pytest

from sjt_pin.bench import reach


def test_random_reaches_keep_every_limit_and_move_to_reaches_what_solve_finds():
    rows = reach.random_reaches(robots=("ur5",), pairs=3, methods=("sjt", "dls"), peers=False)
    by = {r.method: r for r in rows}
    assert set(by) == {"sjt", "dls", "move_to"}
    for r in rows:
        assert r.worst_speed <= 1 + 1e-9 and r.in_range
        assert r.peer_only is None and r.only is None  # no pink asked for
        assert 0.0 <= r.failures <= 1.0
        assert math.isnan(r.median_miss) == (r.failures == 0.0)
    assert by["sjt"].pairs == 3 and 1 <= by["move_to"].pairs <= 3
    assert by["move_to"].failures == 0.0
    table = reach.reach_table(rows).splitlines()
    assert len(table) == 2 + len(rows) and table[2].startswith("| ur5 | sjt | 3 |")


def test_the_pairs_are_drawn_reproducibly():
    one = reach.random_reaches(robots=("ur5",), pairs=2, methods=("sjt",), peers=False)
    two = reach.random_reaches(robots=("ur5",), pairs=2, methods=("sjt",), peers=False)
    assert one == two


def test_the_jerk_grid_settles_within_its_limits():
    rows = reach.jerk_grid(trials=2, robots=("ur5", "panda"), seconds=5.0)
    assert [r.robot for r in rows] == ["ur5", "panda"]
    for r in rows:
        assert 1.0 <= r.acceleration <= 50.0 and 10.0 <= r.ratio <= 1e4
        assert 1e-3 <= r.distance <= 1.0
        assert r.worst_limit <= 1.01
        assert np.isfinite(r.rest) and r.final_error < 1e-6
        assert math.isnan(r.ruckig) or r.ruckig > 0
    table = reach.jerk_table(rows).splitlines()
    assert len(table) == 4 and table[2].startswith("| ur5 |")


def test_ruckig_duration_of_one_joint_matches_the_closed_form():
    # far enough to reach both the acceleration and the speed limit: a jerk-limited trapezoid
    # takes d / v + v / a + a / j
    d, v, a, j = 2.0, 1.0, 4.0, 40.0
    duration = reach.ruckig_duration(np.zeros(1), np.full(1, d), [v], [a], [j])
    assert duration == pytest.approx(d / v + v / a + a / j, rel=1e-6)
