"""``sjt-pin bench accuracy``'s priority tables (``bench.whole_body``) on short runs: a posture
at the lowest level costs the circle nothing and holds the self-motion still, and TALOS keeps
its soles, its centre of mass and its hands where the scene puts them, beside pink's run."""

import math

import pytest

from sjt_pin.bench import whole_body


def test_a_posture_at_the_lowest_level_costs_the_circle_nothing_and_stops_the_drift():
    rows = whole_body.posture_rows(robots=("xarm7",), methods=("sjt",), seconds=12.0)
    (row,) = rows
    assert (row.robot, row.method, row.seconds) == ("xarm7", "SJT", 12.0)
    assert row.plain < 1e-5 and row.ratio <= whole_body.POSTURE_RATIO_TARGET
    assert row.weighted > 100 * row.below  # a weighted posture on the tasks' level biases them
    assert row.drift_plain > 0.1  # without it the self-motion wanders ...
    assert row.settled_below < 1e-3  # ... with it, after the first turn, the motion is periodic
    assert row.drift_below < 0.05 and row.drift_error < 1e-3
    table = whole_body.posture_table(rows).splitlines()
    assert len(table) == 3 and table[2].startswith("| xarm7 | SJT |")


@pytest.fixture(scope="module")
def short_scene():
    """The humanoid scene with a 0.5 s reach held 0.3 s, SJT only, and pink when installed."""
    return whole_body.whole_body_rows(methods=("sjt",), reach_seconds=0.5, hold_seconds=0.3)


def test_the_humanoid_holds_its_soles_and_centre_of_mass_and_reaches(short_scene):
    row = short_scene[0]
    assert row.solver == "SJT" and row.steps == 800
    assert row.hand_error < 1e-4
    assert row.slip < 1e-6
    assert row.com_margin >= 0.0
    assert row.limit_violation == 0.0
    assert row.holds
    assert 0 < row.floor.median < row.step.median <= row.step.p90 <= row.step.max
    assert row.ratio == pytest.approx(row.step.median / row.floor.median)


@pytest.mark.bench
def test_pinks_rows_measure_the_same_scene(short_scene):
    pinks = [r for r in short_scene if r.solver.startswith("pink")]
    assert len(pinks) == 2 and {"costs" in r.solver for r in pinks} == {True, False}
    for r in pinks:
        assert r.steps == 800 and math.isfinite(r.com_margin) and r.floor.median > 0
        assert r.hand_error < 1e-2 and r.slip < 1e-3  # a weighted compromise, near the targets


def test_the_whole_body_table_renders(short_scene):
    table = whole_body.whole_body_table(short_scene).splitlines()
    assert len(table) == 2 + len(short_scene)
    assert table[2].startswith("| SJT | ") and table[2].count("|") == table[0].count("|")


def test_the_scene_without_peers_has_no_pink_row():
    rows = whole_body.whole_body_rows(methods=("dls",), peers=False, reach_seconds=0.1,
                                      hold_seconds=0.05)
    assert [r.solver for r in rows] == ["DLS"] and rows[0].steps == 150
