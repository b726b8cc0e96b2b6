"""The README runs as written: its example prints what it shows, and the quick start is what CI
runs; the site's extending page's task has the rows of its error's derivative."""

import re
from pathlib import Path

from .doc_examples import examples, outputs_match, run_page

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
EXAMPLES = examples(README)


def test_the_readme_is_short_and_has_an_example_with_its_output():
    assert len(README.splitlines()) <= 200
    assert EXAMPLES and all(e.shown for e in EXAMPLES)


def test_the_readme_examples_print_what_they_show(tmp_path):
    printed = run_page(EXAMPLES, tmp_path)
    assert len(printed) == len(EXAMPLES)
    for example, result in zip(EXAMPLES, printed, strict=True):
        assert result["error"] is None, result["error"]
        assert outputs_match(example.shown, result["out"]), (
            f"README line {example.line} shows\n{example.shown}\nbut printed\n{result['out']}")


def test_the_readme_links_into_every_page_of_the_site():
    pages = sorted(p.name for p in (ROOT / "docs").glob("*.md") if p.name != "index.md")
    for name in pages:
        assert f"(docs/{name})" in README, name


def test_ci_runs_the_readme_quick_start_in_order():
    quick_start = re.search(r"## Quick start\n.*?```bash\n(.*?)```", README, re.S).group(1)
    commands = [line.split("#")[0].strip() for line in quick_start.strip().splitlines()]
    assert len(commands) == 2
    ci = [line.split("#")[0].strip() for line in (ROOT / ".ci" / "run").read_text().splitlines()]
    ci = [line for line in ci if line]
    # both, one after the other, in one environment (then the site, the type check and the
    # other environments' jobs: the wheel job, .ci/wheel.sh, runs the slow tests)
    first = ci.index(commands[0])
    assert ci[first:first + 2] == commands
    assert "python -m mypy" in ci[first + 2:]


def test_the_extend_it_task_rows_are_the_derivative_of_its_error(rng):
    """The README's AxisTask: e = z x z_d, whose derivative is -J (finite differences on q)."""
    import numpy as np
    import pinocchio as pin

    import sjt_pin as sjt

    page = (ROOT / "docs" / "extending.md").read_text()
    snippet = next(e.code for e in examples(page) if "class AxisTask" in e.code)
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
