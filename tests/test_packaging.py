"""The wheel carries the generated URDF, so Robot.planar3() works from an installed package."""

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_wheel_ships_planar3_urdf_and_generator(tmp_path):
    build = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", ".", "--no-deps", "-q", "-w", str(tmp_path)],
        capture_output=True, text=True, timeout=600,
    )
    assert build.returncode == 0, build.stderr
    (wheel,) = tmp_path.glob("sjt_pin-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    assert "sjt_pin/robots/planar3.urdf" in names
    assert "sjt_pin/robots/planar3.py" in names
    assert not any("__pycache__" in n or n.startswith("tests/") for n in names)
    assert "sjt_pin/py.typed" in names  # type hints are part of the API (PEP 561)
    # every package of the source tree, the compiled kernels, and no kernel source
    packages = {str(p.parent.relative_to(ROOT)) for p in (ROOT / "sjt_pin").rglob("__init__.py")}
    assert all(f"{package}/__init__.py" in names for package in packages), packages
    assert any(n.startswith("sjt_pin/kernels/_core.") for n in names)
    assert not any(n.startswith("sjt_pin/kernels/src/") for n in names)
    assert any(n.endswith("LICENSE") for n in names)
    # installed apart from the source tree, the URDF is found as package data
    target = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target",
                    str(target), str(wheel)], check=True, timeout=600)
    # (an editable install's import hook, which maps sjt_pin to the source tree, is left out)
    code = ("import sys; sys.path.insert(0, sys.argv[1]); "
            "sys.meta_path[:] = [f for f in sys.meta_path if 'Redirect' not in type(f).__name__]; "
            "import sjt_pin; "
            "assert sjt_pin.__file__.startswith(sys.argv[1]), sjt_pin.__file__; "
            "r = sjt_pin.Robot.planar3(); print(r.nq, r.urdf)")
    run = subprocess.run([sys.executable, "-c", code, str(target)], capture_output=True,
                         text=True, timeout=120, cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    nq, urdf = run.stdout.split()
    assert nq == "3" and urdf.startswith(str(target))


def test_the_version_is_one():
    """``sjt_pin.__version__`` is the version pip installs (pyproject.toml)."""
    from pathlib import Path

    import tomllib

    import sjt_pin

    root = Path(__file__).resolve().parents[1]
    assert tomllib.loads((root / "pyproject.toml").read_text())["project"]["version"] == \
        sjt_pin.__version__


def test_the_core_runs_without_the_extras():
    """With the viewer's and the paper's packages unimportable (as after a bare
    ``pip install .``), a robot steps and solves, and importing the viewer or the figures
    names the extra to install."""
    code = """
import sys
for name in ["meshcat", "trimesh", "fast_simplification", "collada", "matplotlib", "yourdfpy"]:
    sys.modules[name] = None  # import fails as if not installed
import numpy as np

import pytest
import sjt_pin as sjt
robot = sjt.Robot.from_example("ur5")
target = robot.fk(robot.q0 + 0.2)
solver = sjt.SJTSolver(robot, dt=1e-3)
q = robot.q0.copy()
for _ in range(300):
    q = solver.step(q, target)
assert solver.error_norm < 1e-9 and solver.solve(target, robot.q0).success
for module, extra in [("sjt_pin.viewer", "viewer"), ("sjt_pin.paper.figures", "paper"),
                      ("sjt_pin.paper.experiments", "paper")]:
    try:
        __import__(module)
    except ImportError as exc:
        assert f"sjt-pin[{extra}]" in str(exc), exc
    else:
        raise AssertionError(module + " imported without its extra")
print("ok")
"""
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0 and result.stdout.strip() == "ok", result.stderr


def test_the_core_dependencies_are_the_core_s():
    """pyproject's core dependencies hold none of the extras' packages."""
    import tomllib

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    core = " ".join(project["dependencies"])
    for package in ["meshcat", "trimesh", "matplotlib", "yourdfpy", "pycollada"]:
        assert package not in core
    assert {"viewer", "paper", "dev"} <= set(project["optional-dependencies"])
