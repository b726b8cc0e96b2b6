"""The README's claims that can be executed: the UR5 snippet and the CI command."""

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def test_readme_ur5_snippet_runs_as_written():
    snippet = re.search(r"## Use\n.*?```python\n(.*?)```", README, re.S).group(1)
    assert len(snippet.strip().splitlines()) <= 15
    result = subprocess.run([sys.executable, "-c", snippet], capture_output=True, text=True,
                            timeout=300, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.strip().splitlines()
    assert lines[-2].startswith("sjt max error") and lines[-1].startswith("jp max error")


def test_ci_runs_the_readme_test_command():
    quick_start = re.search(r"## Quick start\n.*?```bash\n(.*?)```", README, re.S).group(1)
    test_command = quick_start.strip().splitlines()[1].split("#")[0].strip()
    ci = (ROOT / ".ci" / "run").read_text().strip().splitlines()
    assert ci[-1] == test_command
