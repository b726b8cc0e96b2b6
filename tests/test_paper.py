"""The paper's facts (Sections 3.3 and 4) as tests, on the same code as ``sjt-pin reproduce``."""

import re
from dataclasses import replace

import numpy as np
import pytest

from sjt_pin.cli import main
from sjt_pin.paper import experiments as paper

SETTINGS = paper.PaperSettings()


def largest(method, number, settings=SETTINGS):
    k_lin = paper.linear_bound(method, number, settings)
    return paper.largest_stable_gain(method, number, k_lin / 2, 2 * k_lin, settings), k_lin


@pytest.mark.parametrize("number", [1, 3])
def test_sjt_largest_stable_gain_is_the_linear_bound(number):
    simulated, k_lin = largest("sjt", number)
    assert simulated == pytest.approx(k_lin, rel=0.05)
    # and both sit next to the paper's 680 (task 1) and 660 (task 3) with dt = 1 ms
    assert simulated == pytest.approx(paper.PAPER_GAINS["sjt"][number - 1], rel=0.05)
    assert 2 / (3 * SETTINGS.dt) <= k_lin  # lambda_max(J D J^T) <= n = 3


def test_sjt_gain_ignores_the_length_unit_jt_gain_scales_as_its_inverse_square():
    base_sjt, _ = largest("sjt", 1)
    base_jt, _ = largest("jt", 1)
    for scale in (0.1, 10.0):
        scaled = replace(SETTINGS, scale=scale)
        assert largest("sjt", 1, scaled)[0] == pytest.approx(base_sjt, rel=0.02)
        assert largest("jt", 1, scaled)[0] == pytest.approx(base_jt / scale**2, rel=0.02)


def test_motion_ellipsoids_of_section_3_3():
    postures = paper.ellipsoids()
    jt_max = np.array([p["jt"].sigma_max for p in postures])
    sjt_max = np.array([p["sjt"].sigma_max for p in postures])
    assert sjt_max.max() / sjt_max.min() < 1.03  # D J^T: nearly constant major axis
    assert jt_max[-1] / jt_max[0] > 1.30  # J^T: grows toward the singularity
    stretched = postures[-1]
    np.testing.assert_allclose(stretched["q"], [np.pi, 0.0])
    for key in ("jt", "sjt"):
        assert stretched[key].sigma_min == pytest.approx(0.0, abs=1e-12)
        assert np.all(np.isfinite(stretched[key].sigma))
        assert np.all(np.isfinite(stretched[key].axes))
        assert np.all(np.isfinite(stretched[key].outline()))


def test_stability_criterion_separates_both_sides_of_the_bound():
    k_lin = paper.linear_bound("sjt", 1)
    assert paper.stability(paper.run("sjt", 1, 0.9 * k_lin)) == (True, "")
    stable, why = paper.stability(paper.run("sjt", 1, 1.1 * k_lin))
    assert not stable and why


def test_task_geometry():
    t1, t2, t3 = (paper.paper_task(n) for n in paper.TASKS)
    for task in (t1, t2):
        np.testing.assert_allclose(task.robot.fk(task.q0).translation[:2], [-0.293, 0.986],
                                   atol=1e-9)
    assert t1.reachable_until == np.inf and t3.reachable_until == np.inf
    exit_point = t2.trajectory.sample(t2.reachable_until)[0].translation
    assert np.linalg.norm(exit_point) == pytest.approx(1.18)
    top = t3.trajectory.sample(t3.trajectory.duration * 0.75)[0].translation  # from angle pi
    np.testing.assert_allclose(top[:2], [0.0, 1.18], atol=1e-12)  # touches the reach


def test_gain_sweep_in_parallel_matches_serial():
    gains = [20.0, 200.0, 2000.0]
    serial = paper.gain_sweep("sjt", 1, gains)
    parallel = paper.gain_sweep("sjt", 1, gains, processes=2)
    np.testing.assert_array_equal(serial.stable, [True, True, False])
    np.testing.assert_allclose(serial.max_errors, parallel.max_errors)
    assert serial.max_errors[0] > serial.max_errors[1]  # higher gain, smaller error (Fig. 6)
    assert serial.largest_stable_gain == pytest.approx(serial.k_lin, rel=0.05)


def test_jp_cannot_follow_task_2_out_of_the_workspace():
    log = paper.run("jp", 2, 100.0)
    assert not paper.stability(log)[0]


@pytest.mark.slow
def test_reproduce_writes_figures_and_results(tmp_path, capsys):
    assert main(["reproduce", "--out", str(tmp_path), "--grid", "3", "--processes", "2"]) == 0
    # not on a terminal (captured): progress comes as plain lines, the last of each stage full
    err = capsys.readouterr().err
    assert re.search(r"^SJT task 3: (\d+)/\1 \(\d+ s\)$", err, re.M), err
    assert re.search(r"^length units: (\d+)/\1 ", err, re.M), err
    names = {p.name for p in tmp_path.iterdir()}
    assert {"results.md", "fig2_3_ellipsoids.png", "fig6a_task1.png", "fig6b_task2.png",
            "fig6c_task3.png", "fig7_task3_errors.png"} <= names
    text = (tmp_path / "results.md").read_text()
    assert "| SJT |" in text and "680.0" in text and "## Length units" in text
    _the_paper_page_shows_this_run(text)


def _the_paper_page_shows_this_run(results: str) -> None:
    """docs/paper.md's table of largest stable gains is the run's: simulated gains within the
    bisection's 0.5 % (``--grid`` moves where it ends), k_lin as rounded, the paper's as given."""
    from pathlib import Path

    page = (Path(__file__).resolve().parents[1] / "docs" / "paper.md").read_text()
    shown = {}
    for label, cells in re.findall(r"^\| ((?:SJT|JT), [^|]+?) \|(.*)\|$", page, re.M):
        shown[label] = [float(c.strip(" *")) for c in cells.split("|")]
    run: dict[str, list[float]] = {}
    for task in re.split(r"^### Task ", results, flags=re.M)[1:4]:
        for method in ("SJT", "JT"):
            row = re.search(rf"^\| {method} \| ([^|]+) \| ([^|]+) \|.*\| ([^|]+) \|$", task, re.M)
            simulated, k_lin, theirs = (float(x) for x in row.groups())
            run.setdefault(f"{method}, simulated", []).append(simulated)
            run.setdefault(f"{method}, k_lin", []).append(k_lin)
            run.setdefault(f"{method}, paper", []).append(theirs)
    label = {"JT, simulated (metres)": "JT, simulated"}
    assert set(shown) == {"SJT, simulated", "SJT, k_lin", "SJT, paper", "JT, simulated (metres)",
                          "JT, paper"}
    for row, values in shown.items():
        expected = run[label.get(row, row)]
        if row.endswith("simulated") or row.endswith("(metres)"):
            assert values == pytest.approx(expected, rel=0.006), row
        else:
            assert values == [round(v) for v in expected], row
