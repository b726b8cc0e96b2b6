import pytest

from sjt_pin.cli import main


def test_demo_prints_one_row_per_robot_and_method(capsys):
    assert main(["demo", "--robot", "planar3", "ur5", "--method", "sjt", "jp"]) == 0
    out = capsys.readouterr().out
    rows = [line.split() for line in out.splitlines() if line.split()[:1] in (["planar3"], ["ur5"])]
    assert [r[:2] for r in rows] == [["planar3", "sjt"], ["planar3", "jp"], ["ur5", "sjt"],
                                     ["ur5", "jp"]]
    for row in rows:
        max_error, rms_error = float(row[2]), float(row[3])
        assert 0 <= rms_error <= max_error < 0.05


def test_unknown_robot_is_refused():
    with pytest.raises(SystemExit):
        main(["demo", "--robot", "r2d2"])
