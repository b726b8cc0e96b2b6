"""The ``sjt-pin demo`` command: its table, its progress, where it writes, what it says.

Every test here writes into a temporary folder only: the autouse fixture fails a test that
leaves a new file in the folder it was started from.
"""

import argparse
import contextlib
import os
import re
import subprocess
import sys
import urllib.error
import urllib.request
import webbrowser
from pathlib import Path

import pytest

import sjt_pin
from sjt_pin.cli import build_parser, main

FAST = ["--robot", "planar3", "--method", "sjt"]


@contextlib.contextmanager
def no_new_files(folder: Path):
    """Raise AssertionError if a file appears in ``folder`` meanwhile (e.g. ./demo.html)."""
    before = set(os.listdir(folder))
    yield
    new = {f for f in set(os.listdir(folder)) - before if not f.startswith(".coverage")}
    assert new == set(), f"new files in {folder}"  # (coverage's data of the tests is not ours)


@pytest.fixture(autouse=True)
def working_folder_left_alone():
    with no_new_files(Path.cwd()):
        yield


def test_demo_prints_progress_and_one_row_per_robot_and_method(capsys):
    assert main(["demo", "--robot", "planar3", "ur5", "--method", "sjt", "jp",
                 "--no-viewer"]) == 0
    out = capsys.readouterr().out
    progress = re.findall(r"\[(\d)/4\] (\w+) (\w+): 4001 steps in", out)
    assert progress == [("1", "planar3", "sjt"), ("2", "planar3", "jp"), ("3", "ur5", "sjt"),
                        ("4", "ur5", "jp")]
    rows = [line.split() for line in out.splitlines() if line.split()[:1] in (["planar3"], ["ur5"])]
    assert [r[:2] for r in rows] == [["planar3", "sjt"], ["planar3", "jp"], ["ur5", "sjt"],
                                     ["ur5", "jp"]]
    for row in rows:
        max_error, rms_error = float(row[2]), float(row[3])
        assert 0 <= rms_error <= max_error < 0.05
    assert "127.0.0.1" not in out and "Wrote" not in out


def test_demo_writes_the_page_where_asked_and_prints_its_size(tmp_path, capsys):
    out = tmp_path / "new" / "page.html"  # a folder that does not exist yet
    assert main(["demo", *FAST, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    size = re.search(rf"Wrote {re.escape(str(out.resolve()))} \((\d+\.\d) MB", printed)
    assert size and float(size.group(1)) == pytest.approx(out.stat().st_size / 1e6, abs=0.05)
    assert "http://" not in printed  # no live viewer without --keep, so no link to it


def test_demo_draws_the_whole_body_scenes_asked_for(tmp_path, capsys):
    """--robot names the page's whole-body scenes too: alone, they make no table; each says
    how its run went; without the page they are not run."""
    from sjt_pin.cli import WHOLE_BODY
    from sjt_pin.viewer.demo import WHOLE_BODY_SCENES

    assert set(WHOLE_BODY) == set(WHOLE_BODY_SCENES)
    out = tmp_path / "d.html"
    assert main(["demo", "--robot", "solo12", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "Tracking" not in printed and "Errors in" not in printed
    assert re.search(r"^  solo12: loading the robot, running its whole-body scene \(SJT\) "
                     r"\.\.\. 4001 steps, [\d.]+ s, max error ", printed, re.M)
    page = out.read_text()
    for label in ("Solo-12 moving its body", "Franka Panda around a ball"):
        assert f"<h2>{label}</h2>" in page
    assert "TALOS" not in page and "Planar 3R arm" not in page
    assert "<p>Behind: a Panda passes a ball" in page  # (no circles to describe)
    assert main(["demo", "--robot", "talos", "ur5", "--method", "sjt", "--no-viewer"]) == 0
    printed = capsys.readouterr().out
    assert "[1/1] ur5 sjt" in printed and "talos" not in printed.split("\n\n")[0]
    assert "talos: drawn on the page only (whole-body scenes), not run with --no-viewer" in printed


def test_demo_writes_demo_html_in_the_working_folder_by_default(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["demo", *FAST]) == 0
    assert os.listdir(tmp_path) == ["demo.html"]


def _working_folder() -> set[str]:
    """The working folder's names, less coverage's data files (which the processes other
    pytest workers start write there meanwhile)."""
    return {name for name in os.listdir() if not name.startswith(".coverage.")}


def test_demo_leaves_no_file_in_the_working_folder(tmp_path):
    before = _working_folder()
    assert main(["demo", *FAST, "--out", str(tmp_path / "demo.html")]) == 0
    assert _working_folder() == before and (tmp_path / "demo.html").exists()


def test_progress_reaches_a_pipe_at_once_and_the_live_link_works_while_announced(tmp_path):
    here = str(Path(sjt_pin.__file__).parents[1])  # the sjt_pin under test
    demo = subprocess.Popen(
        [sys.executable, "-m", "sjt_pin.cli", "demo", *FAST, "--out", str(tmp_path / "d.html"),
         "--keep", "4"], stdout=subprocess.PIPE, text=True, cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": here})
    try:
        lines = []
        while not lines or not lines[-1].startswith("Live viewer at"):
            lines.append(demo.stdout.readline())
            assert lines[-1], "the demo ended without announcing the live viewer"
        # the lines came while the demo still runs: stdout, a pipe here, is flushed
        assert demo.poll() is None
        assert any(line.startswith("  [1/1] planar3 sjt") for line in lines)
        url = re.search(r"http://127\.0\.0\.1:\d+/static/", lines[-1]).group(0)
        assert "for the next 4 s" in lines[-1]
        with urllib.request.urlopen(url, timeout=5) as page:
            assert page.status == 200
        assert demo.wait(timeout=30) == 0
    finally:
        demo.kill()
        demo.wait()
    assert demo.stdout.read().startswith("Live viewer stopped")
    with pytest.raises(urllib.error.URLError):
        urllib.request.urlopen(url, timeout=5)


class Browser:
    """A stand-in for a web browser that records what it was asked to open."""

    def __init__(self, works: bool):
        self.works, self.opened = works, []

    def open(self, url, new=0, autoraise=True):
        self.opened.append(url)
        return self.works


def test_open_opens_the_page(tmp_path, capsys, monkeypatch):
    browser = Browser(works=True)
    monkeypatch.setattr(webbrowser, "get", lambda using=None: browser)
    assert main(["demo", *FAST, "--out", str(tmp_path / "d.html"), "--open"]) == 0
    assert browser.opened == [(tmp_path / "d.html").resolve().as_uri()]
    assert "Opened it in the web browser" in capsys.readouterr().out


@pytest.mark.parametrize("case", ["no browser", "browser fails"])
def test_open_without_a_browser_says_so(case, tmp_path, capsys, monkeypatch):
    def get(using=None):
        if case == "no browser":
            raise webbrowser.Error("could not locate runnable browser")
        return Browser(works=False)

    monkeypatch.setattr(webbrowser, "get", get)
    assert main(["demo", *FAST, "--out", str(tmp_path / "d.html"), "--open"]) == 0
    out = capsys.readouterr().out
    assert "no web browser found" in out and (tmp_path / "d.html").resolve().as_uri() in out


def test_every_demo_option_has_help():
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    options = [a for a in sub.choices["demo"]._actions if a.dest != "help"]
    assert {a.dest for a in options} == {"robot", "method", "out", "open", "no_viewer", "keep"}
    assert all(a.help and a.help != argparse.SUPPRESS for a in options)


def test_unknown_robot_is_refused():
    with pytest.raises(SystemExit):
        main(["demo", "--robot", "r2d2"])


def test_the_working_folder_guard_catches_a_stray_file(tmp_path):
    with pytest.raises(AssertionError, match="new files"), no_new_files(tmp_path):
        (tmp_path / "demo.html").write_text("stray")


def bad_arguments(tmp: Path) -> dict[str, list[str]]:
    """Command lines with one bad argument each, and (key) what is wrong."""
    (tmp / "a_file").write_text("")
    (tmp / "a_folder").mkdir()
    file, folder = str(tmp / "a_file"), str(tmp / "a_folder")
    return {
        "demo --out ''": ["demo", *FAST, "--out", ""],
        "demo --out a folder": ["demo", *FAST, "--out", folder],
        "demo --out under a file": ["demo", *FAST, "--out", file + "/page.html"],
        "demo --out unwritable": ["demo", *FAST, "--out", "/proc/page.html"],
        "demo --keep -1": ["demo", *FAST, "--keep", "-1"],
        "demo --keep nan": ["demo", *FAST, "--keep", "nan"],
        "bench speed --steps 0": ["bench", "speed", "--steps", "0"],
        "bench speed --steps x": ["bench", "speed", "--steps", "x"],
        "bench ik --poses 0": ["bench", "ik", "--poses", "0"],
        "bench --json missing folder": ["bench", "ik", "--json", str(tmp / "no" / "r.json")],
        "bench --json a folder": ["bench", "ik", "--json", folder],
        "bench --json ''": ["bench", "ik", "--json", ""],
        "bench --json unwritable": ["bench", "ik", "--json", "/proc/r.json"],
        "reproduce --grid 0": ["reproduce", "--grid", "0"],
        "reproduce --grid 1": ["reproduce", "--grid", "1"],
        "reproduce --processes 0": ["reproduce", "--processes", "0"],
        "reproduce --out a file": ["reproduce", "--out", file],
        "reproduce --out ''": ["reproduce", "--out", ""],
        "reproduce --out unwritable": ["reproduce", "--out", "/proc/results"],
        "no command": [],
    }


@pytest.mark.parametrize("case", [
    "demo --out ''", "demo --out a folder", "demo --out under a file", "demo --out unwritable",
    "demo --keep -1", "demo --keep nan", "bench speed --steps 0", "bench speed --steps x",
    "bench ik --poses 0", "bench --json missing folder", "bench --json a folder",
    "bench --json ''", "bench --json unwritable", "reproduce --grid 0", "reproduce --grid 1",
    "reproduce --processes 0", "reproduce --out a file", "reproduce --out ''",
    "reproduce --out unwritable", "no command"])
def test_a_bad_argument_is_one_line_and_exit_code_2_before_any_work(case, tmp_path, capsys):
    argv = bad_arguments(tmp_path)[case]
    before = sorted(p.name for p in tmp_path.iterdir())
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    assert exit_.value.code == 2
    out, err = capsys.readouterr()
    assert out == ""  # nothing ran: the demo and the benchmarks print as they start
    assert len(err.strip().splitlines()) == 1 and ": error: " in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # and nothing was written


def test_a_bad_argument_gives_no_traceback_from_the_command_line(tmp_path):
    here = str(Path(sjt_pin.__file__).parents[1])
    run = subprocess.run([sys.executable, "-m", "sjt_pin.cli", "bench", "ik", "--json",
                          str(tmp_path / "missing" / "r.json")], capture_output=True, text=True,
                         cwd=tmp_path, env={**os.environ, "PYTHONPATH": here}, timeout=120)
    assert run.returncode == 2 and run.stdout == ""
    assert run.stderr == (f"sjt-pin bench: error: argument --json: the folder of "
                          f"'{tmp_path / 'missing' / 'r.json'}' does not exist "
                          "(see sjt-pin bench --help)\n")


def test_good_output_paths_pass_and_leave_nothing_behind(tmp_path):
    parser = build_parser()
    args = parser.parse_args(["demo", "--out", str(tmp_path / "new" / "deeper" / "d.html")])
    assert args.out == tmp_path / "new" / "deeper" / "d.html"
    args = parser.parse_args(["reproduce", "--out", str(tmp_path / "results"), "--grid", "2"])
    assert args.out == tmp_path / "results" and args.grid == 2
    args = parser.parse_args(["bench", "speed", "--json", str(tmp_path / "r.json")])
    assert args.json == tmp_path / "r.json"
    assert list(tmp_path.iterdir()) == []  # checked by writing, but nothing is left


def test_help_has_no_rest_markup_and_every_command_a_description(capsys):
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for argv in ([], *([name] for name in sub.choices)):
        with pytest.raises(SystemExit):
            parser.parse_args([*argv, "--help"])
        text = capsys.readouterr().out
        assert "``" not in text and ":func:" not in text, argv
    for name, command in sub.choices.items():
        assert command.description, name


def test_robots_lists_every_name_from_example_takes(capsys):
    from example_robot_data.robots_loader import ROBOTS

    assert main(["robots"]) == 0
    out = capsys.readouterr().out
    listed = out.split(":", 1)[1].split()
    assert sorted(listed) == sorted(ROBOTS) and "ur5" in listed and "panda" in listed
    assert f"{len(ROBOTS)} robots" in out
