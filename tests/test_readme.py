"""The README runs as written: every Python snippet, and the quick start is what CI runs."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
SNIPPETS = re.findall(r"```python\n(.*?)```", README, re.S)


def test_the_readme_has_snippets():
    assert len(SNIPPETS) >= 5


@pytest.mark.parametrize("index", range(len(SNIPPETS)))
def test_snippet_runs_as_written(index, tmp_path):
    """Each snippet on its own, in an empty folder: nothing it needs is left undefined."""
    result = subprocess.run([sys.executable, "-c", SNIPPETS[index]], capture_output=True,
                            text=True, timeout=600, cwd=tmp_path)
    assert result.returncode == 0, f"snippet {index}:\n{SNIPPETS[index]}\n{result.stderr}"


def test_ci_runs_the_readme_quick_start_in_order():
    quick_start = re.search(r"## Quick start\n.*?```bash\n(.*?)```", README, re.S).group(1)
    commands = [line.split("#")[0].strip() for line in quick_start.strip().splitlines()]
    assert len(commands) == 2
    ci = [line.split("#")[0].strip() for line in (ROOT / ".ci" / "run").read_text().splitlines()]
    ci = [line for line in ci if line]
    # both, one after the other, in one environment (then the slow tests, the type check and
    # the other environments' jobs)
    first = ci.index(commands[0])
    assert ci[first:first + 2] == commands
    assert "python -m mypy" in ci[first + 2:]


def test_the_extend_it_task_rows_are_the_derivative_of_its_error(rng):
    """The README's AxisTask: e = z x z_d, whose derivative is -J (finite differences on q)."""
    import numpy as np
    import pinocchio as pin

    import sjt_pin as sjt

    snippet = next(s for s in SNIPPETS if "class AxisTask" in s)
    namespace: dict = {}
    exec(snippet.split("\nur5 = ")[0], namespace)
    ur5 = sjt.Robot.from_example("ur5")
    task = namespace["AxisTask"]("wrist_3_link").bind(ur5)
    kinematics = sjt.Kinematics(ur5.model)

    def rows(q, target):
        kinematics.update(q)
        J, e, _ = task.compute(kinematics, target, None)
        return J.copy(), e.copy()

    for _ in range(3):
        q = ur5.random_configuration(rng)
        target = task.target(rng.normal(size=3))
        J, e = rows(q, target)
        assert np.linalg.norm(e) > 0.05
        finite = np.empty((3, ur5.nv))
        for i in range(ur5.nv):
            dv = np.zeros(ur5.nv)
            dv[i] = 1e-6
            plus = rows(pin.integrate(ur5.model, q, dv), target)[1]
            minus = rows(pin.integrate(ur5.model, q, -dv), target)[1]
            finite[:, i] = (plus - minus) / 2e-6
        np.testing.assert_allclose(finite, -J, atol=1e-6)


def test_the_extend_it_two_frame_task_rows_and_joints(rng):
    """The README's HandOffset: its rows are -de/dq (finite differences on q), and the joints
    it leaves out (legs, head) have zero columns."""
    import numpy as np
    import pinocchio as pin

    import sjt_pin as sjt

    snippet = next(s for s in SNIPPETS if "class HandOffset" in s)
    namespace: dict = {}
    exec(snippet.split("\ntalos = ")[0], namespace)
    talos = sjt.Robot.from_example("talos")
    task = namespace["HandOffset"]("gripper_left_joint", "gripper_right_joint").bind(talos)
    kinematics = sjt.Kinematics(talos.model)
    moved = np.zeros(talos.nv, dtype=bool)
    for j in task.joints(talos.model):
        joint = talos.model.joints[j]
        moved[joint.idx_v:joint.idx_v + joint.nv] = True
    names = {talos.model.names[j] for j in task.joints(talos.model)}
    assert {"arm_left_1_joint", "arm_right_1_joint", "torso_1_joint"} <= names
    assert not any("leg" in n or "head" in n for n in names), names

    def error(q, target):
        kinematics.update(q)
        J, e, _ = task.compute(kinematics, target, None)
        return J.copy(), e.copy()

    q = talos.q0.copy()
    q[7:] += rng.uniform(-0.3, 0.3, talos.nq - 7)
    J, _ = error(q, np.zeros(3))
    finite = np.empty((3, talos.nv))
    for i in range(talos.nv):
        dv = np.zeros(talos.nv)
        dv[i] = 1e-6
        plus = error(pin.integrate(talos.model, q, dv), np.zeros(3))[1]
        minus = error(pin.integrate(talos.model, q, -dv), np.zeros(3))[1]
        finite[:, i] = (plus - minus) / 2e-6
    np.testing.assert_allclose(finite, -J, atol=1e-6)
    assert np.abs(J[:, ~moved]).max() < 1e-12
