"""The notebooks run top to bottom, headless, from outside the checkout, and are committed
without outputs.

Each notebook is executed once (a module-scoped fixture) the way a user's Jupyter runs it: the
kernel's own matplotlib backend (the inline one: ``MPLBACKEND`` is not set), its working folder
an empty temporary folder, ``TMPDIR`` another one, and no ``PYTHONPATH``, so that ``sjt_pin`` is
the *installed* package (the editable install of the dev setup), not the checkout by accident.
A probe cell appended to the executed copy reports where ``sjt_pin`` came from and the backend.
``SJT_PIN_QUICK=1`` shortens the sweeps (same code).

The same check runs on a small script, and on that script with a stale ``sjt_pin/`` folder
(left-over cache files, no ``__init__.py``) on its path: such a namespace package shadows an
editable install for every process outside the checkout, and the check must catch it.
"""

import json
import os
import re
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
CELL_TIMEOUT = 600  # s per cell: generous, for a loaded machine
#: s per notebook under SJT_PIN_QUICK=1: about 10-20 s on 2 cores;
#: the first run on a machine also compiles the kernels (about 35 s more, in the first notebook)
TIME_LIMIT = 120
#: code that draws a matplotlib figure: a cell with it must show an image
FIGURE_CALL = re.compile(r"\bplt\.(subplots|figure|plot|loglog|semilogy)\(|"
                         r"\bfigures\.\w+_figure\(")

pytestmark = pytest.mark.slow  # the notebooks executed: minutes (CI runs them with -m slow)

INLINE = "module://matplotlib_inline.backend_inline"
MARK = "SJT_PIN_PROBE "
#: reports where sjt_pin was imported from (run last in each notebook, and by the script)
PROBE = f"""
import json as _json, os as _os, sys as _sys
import matplotlib as _mpl
import sjt_pin as _sjt_pin

def _leftovers():
    # (an editable install's compiled part, sjt_pin/kernels/_core*.so beside no .py file, is
    # the install itself: its finder maps the package to the checkout)
    found = []
    for entry in _sys.path:
        folder = _os.path.join(entry or _os.getcwd(), "sjt_pin")
        if _os.path.isdir(folder) and not _os.path.isfile(_os.path.join(folder, "__init__.py")):
            files = [f for _, _, names in _os.walk(folder) for f in names]
            if not files or any(not f.endswith((".so", ".pyd")) for f in files):
                found.append(folder)
    return found

print({MARK!r} + _json.dumps({{
    "file": getattr(_sjt_pin, "__file__", None), "has_robot": hasattr(_sjt_pin, "Robot"),
    "path": list(_sjt_pin.__path__), "sys_path": _sys.path, "cwd": _os.getcwd(),
    "leftovers": _leftovers(), "backend": _mpl.get_backend()}}), flush=True)
"""
#: a small user script: the probe, then real work with the installed package
SCRIPT = PROBE + """
import numpy as np
import sjt_pin as sjt
from sjt_pin.bench import accuracy  # noqa: F401 (the subpackages resolve)
from sjt_pin.paper import experiments

robot = sjt.Robot.planar3()  # the URDF ships as package data (sjt_pin.robots)
task = experiments.paper_task(3)
log = sjt.track(sjt.SJTSolver(robot, task=sjt.PositionTask(axes="xy")), task.trajectory, task.q0)
assert log.max_error < 1e-3, log.max_error
print("ok", log.max_error)
"""


def outside_env(tmp: Path) -> dict[str, str]:
    """The environment of a process outside the checkout: no PYTHONPATH (only the installed
    package), the backend left to the process (no MPLBACKEND), temporary files under ``tmp``."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "MPLBACKEND")}
    env["TMPDIR"] = str(tmp)
    return env


def probe_report(text: str) -> dict:
    lines = [line for line in text.splitlines() if line.startswith(MARK)]
    assert lines, f"the probe printed nothing:\n{text}"
    return json.loads(lines[-1][len(MARK):])


def check_installed(report: dict, cwd: Path) -> None:
    """``sjt_pin`` was imported from a real package (its ``__init__.py``, with ``Robot``), not
    from a namespace leftover (``__file__`` None, no ``Robot``), and not off the checkout's
    root through ``sys.path`` or the working folder."""
    assert not report["leftovers"], (
        f"stale sjt_pin/ folders without __init__.py on sys.path (they shadow the installed "
        f"package): {report['leftovers']}")
    assert report["file"] is not None and report["has_robot"], (
        f"sjt_pin is a namespace package from {report['path']}, not the installed package")
    init = Path(report["file"])
    assert init.name == "__init__.py" and init.is_file(), init
    assert (init.parent / "solvers.py").is_file(), f"{init.parent} is not the sjt_pin package"
    assert Path(report["cwd"]).resolve() == cwd.resolve()
    if not init.resolve().is_relative_to(ROOT.resolve()):  # (an editable install's .pth
        # puts the checkout's root on sys.path: its package is the checkout's by design)
        searched = {Path(p or report["cwd"]).resolve() for p in report["sys_path"]}
        assert ROOT.resolve() not in searched, "the checkout's root is on sys.path"


def test_the_three_notebooks_exist():
    assert [p.name for p in NOTEBOOKS] == ["01_paper_planar_arm.ipynb", "02_panda.ipynb",
                                           "03_ur5.ipynb"]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_committed_without_outputs(path):
    notebook = json.loads(path.read_text())
    for cell in notebook["cells"]:
        if cell["cell_type"] == "code":
            assert cell["outputs"] == [] and cell["execution_count"] is None, (
                f"{path.name} has outputs: strip them (nbstripout, or clear them in Jupyter)")


@dataclass
class Run:
    path: Path
    cells: list  # the executed code cells, the probe last
    work: Path  # the kernel's working folder
    tmp: Path  # its TMPDIR
    seconds: float
    error: Exception | None


@pytest.fixture(scope="module", params=NOTEBOOKS, ids=lambda p: p.stem)
def run(request, tmp_path_factory) -> Run:
    """Execute one notebook headless, outside the checkout, with the probe cell appended."""
    import nbformat
    from nbclient import NotebookClient

    path = request.param
    base = tmp_path_factory.mktemp(path.stem)
    work, tmp = base / "work", base / "tmp"
    work.mkdir()
    tmp.mkdir()
    env = outside_env(tmp)
    env["SJT_PIN_QUICK"] = "1"  # shorter sweeps, same code
    notebook = nbformat.read(path, as_version=4)
    notebook.cells.append(nbformat.v4.new_code_cell(PROBE))
    client = NotebookClient(notebook, timeout=CELL_TIMEOUT, kernel_name="python3",
                            resources={"metadata": {"path": str(work)}})
    start, error = time.perf_counter(), None
    try:
        client.execute(env=env)
    except Exception as exc:  # noqa: BLE001 (reported by test_notebook_executes)
        error = exc
    cells = [c for c in notebook.cells if c.cell_type == "code"]
    return Run(path, cells, work, tmp, time.perf_counter() - start, error)


def test_notebook_executes(run):
    if run.error is not None:
        raise run.error  # CellExecutionError: the failing cell and its traceback
    errors = [o for c in run.cells for o in c.outputs if o.get("output_type") == "error"]
    assert not errors
    assert run.seconds < TIME_LIMIT, f"{run.path.name} took {run.seconds:.0f} s"


def test_figures_show(run):
    """Every cell that draws a figure shows it as an image, with the kernel's own backend."""
    assert run.error is None, "the notebook failed (see test_notebook_executes)"
    promised = [c for c in run.cells if FIGURE_CALL.search(c.source)]
    for cell in promised:
        images = [o for o in cell.outputs if "image/png" in o.get("data", {})]
        assert images, f"{run.path.name}: no image from the cell\n{cell.source}"
    report = probe_report("".join(o.get("text", "") for o in run.cells[-1].outputs))
    assert report["backend"] == INLINE, report["backend"]


def test_runs_against_the_installed_package(run):
    assert run.error is None, "the notebook failed (see test_notebook_executes)"
    report = probe_report("".join(o.get("text", "") for o in run.cells[-1].outputs))
    check_installed(report, run.work)


def test_writes_nothing_and_keeps_a_static_copy_of_each_view(run):
    """No file in the working folder, no temporary folder left (they used to stay, 1.5-2 MB
    each), and each viewer made has a static copy of its page in the cell outputs, which the
    saved notebook keeps after the kernel stopped (a live view is an iframe on a server)."""
    assert run.error is None, "the notebook failed (see test_notebook_executes)"
    assert not any(run.work.iterdir()), (
        f"{run.path.name} wrote into its working folder: {sorted(run.work.iterdir())}")
    left = sorted(p.name for p in run.tmp.iterdir() if p.name.startswith("sjt-pin"))
    assert left == [], f"{run.path.name} left temporary folders: {left}"
    viewers = sum(len(re.findall(r"\bViewer\(", c.source)) for c in run.cells)
    copies = [o["data"]["text/html"] for c in run.cells for o in c.outputs
              if "srcdoc=" in o.get("data", {}).get("text/html", "")]
    assert viewers > 0 and len(copies) >= viewers, (viewers, len(copies))
    for page in copies:  # the whole page: meshcat's script, the scene, the page's script
        assert "new MeshCat.Viewer" in page and "sjt-scene" in page and "127.0.0.1" not in page


def test_a_script_outside_the_checkout_uses_the_installed_package(tmp_path):
    work, tmp = tmp_path / "work", tmp_path / "tmp"
    work.mkdir()
    tmp.mkdir()
    done = subprocess.run([sys.executable, "-c", SCRIPT], cwd=work, env=outside_env(tmp),
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    check_installed(probe_report(done.stdout), work)
    assert "ok" in done.stdout.splitlines()[-1]
    assert not any(work.iterdir()), sorted(work.iterdir())


def test_the_check_catches_a_namespace_leftover(tmp_path):
    """A ``sjt_pin/`` folder of left-over cache files (no ``__init__.py``) on the path: where it
    shadows the install (``sjt_pin`` imports as an empty namespace package) the check fails;
    an editable install's finder comes first and is not shadowed."""
    site, work = tmp_path / "site", tmp_path / "work"
    cache = site / "sjt_pin" / "kernels" / "__pycache__"
    cache.mkdir(parents=True)
    (cache / "methods.sjt_step-42.py311.nbi").write_bytes(b"")
    work.mkdir()
    env = outside_env(tmp_path)
    env["PYTHONPATH"] = str(site)
    done = subprocess.run([sys.executable, "-c", SCRIPT], cwd=work, env=env,
                          capture_output=True, text=True, timeout=600)
    report = probe_report(done.stdout)
    if done.returncode == 0:  # an editable install's finder: the leftover shadows nothing
        assert report["has_robot"] and report["file"] is not None
        return
    with pytest.raises(AssertionError, match="stale sjt_pin"):
        check_installed(report, work)
    report["leftovers"] = []  # without the folder test, the namespace package itself fails it
    with pytest.raises(AssertionError, match="namespace package"):
        check_installed(report, work)


def test_figures_leave_the_backend_alone(tmp_path):
    """Importing the figures (and the reproduce command) keeps the process's backend: a
    notebook's inline backend must survive ``from sjt_pin.paper import figures``."""
    code = ("import matplotlib; matplotlib.use('svg'); "
            "import matplotlib.pyplot as plt; "
            "from sjt_pin.paper import figures, reproduce; "
            "print(matplotlib.get_backend())")
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=outside_env(tmp_path),
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split()[-1] == "svg"


def _code(path: Path) -> list[str]:
    return ["".join(c["source"]) for c in json.loads(path.read_text())["cells"]
            if c["cell_type"] == "code"]


@pytest.mark.parametrize("name", ["02_panda", "03_ur5"])
def test_methods_have_the_viewers_colours(name):
    """Every line drawn per method takes its colour from the viewer's palette (one palette for
    the pages and the plots: matplotlib's own cycle gave other colours)."""
    code = _code(ROOT / "notebooks" / f"{name}.ipynb")
    assert any("method_color(" in cell for cell in code)
    calls = [m.group(0) for cell in code
             for m in re.finditer(r"\.(plot|semilogy|loglog)\((?:[^()]|\([^()]*\))*\)", cell)
             if "label=name" in m.group(0) or "label=variant" in m.group(0)]
    assert calls and all("color=COLORS[" in call for call in calls), calls


def test_the_path_figure_has_axis_labels():
    cell = next(c for c in _code(ROOT / "notebooks" / "01_paper_planar_arm.ipynb")
                if "desired paths" in c)
    assert 'set_xlabel("x [m]")' in cell and 'set_ylabel("y [m]")' in cell
