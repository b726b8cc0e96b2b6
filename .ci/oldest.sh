#!/usr/bin/env bash
# CI job "oldest": the core's dependencies at exactly the lower bounds pyproject.toml declares
# (pin, example-robot-data-loaders, lxml, numpy, tqdm: each ">=X" installed as "==X"), the
# project installed from the checkout (`pip install .`, no extra: the build pulls its own
# numpy >= 2 headers in isolation), and the core's tests, the ones that need no extra, run
# against that install. A declared floor that does not work fails this job.
# Run from anywhere; reads the checkout only (everything it makes is under one temp dir, removed
# on success, kept and named on failure). Env: PYTHON (default python3, >= 3.11 for tomllib;
# requires-python's floor, 3.10, is not what this job runs on).
# Extra arguments go to pytest. Time on 2 cores, warm pip cache, with another job keeping them
# busy (load 7-9): 333 s and 524 s, most of it the C++ build (80 s alone, 185-363 s loaded);
# a cold cache adds the downloads (example-robot-data 5.0.0's wheel is 133 MB).
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
PY=${PYTHON:-python3}
WORK=$(mktemp -d /tmp/ci-oldest.XXXXXX)
START=$SECONDS
trap 'rc=$?; if ((rc == 0)); then rm -rf "$WORK"; else echo "oldest.sh: FAILED (rc=$rc), files kept in $WORK" >&2; fi' EXIT

# the core's test files that need no extra (no viewer, paper, scipy, cluster or bench) and not
# the checkout's own files; test_pipeline.py is left out: it imports sjt_pin.robots.planar3,
# which needs yourdfpy (the paper extra)
TESTS=(
  test_solvers test_tasks test_robot test_bad_input test_frames test_kernels test_solve
  test_limits test_copies test_random_urdfs test_seeds_outside test_stalled test_restarts
  test_least_squares_rest test_multi test_relative_pose test_target_hint test_tracking
  test_trajectories test_feedforward test_distances test_braking
  test_example_frames test_example_urdfs test_urdf_semantics test_urdf_errors
  test_collision_speed test_collision_mesh test_collision_moving test_boundary_collision
  test_boundary_search test_whole_body
)
# nodes that read the checkout's robots/ (as in .ci/wheel.sh), or build random chains with
# yourdfpy (the paper extra)
DESELECT=(
  test_whole_body.py::test_a_lower_level_costs_the_top_level_nothing
  test_urdf_errors.py::test_bytes_path_and_text_give_the_same_robot
  test_urdf_errors.py::test_single_package_dir_is_one_folder
  test_urdf_errors.py::test_paper_planar3_urdf_passes_the_checks
)

# the floors: every core dependency "name>=X" of pyproject.toml becomes "name==X"; one without
# a lower bound fails the job (its floor would not be tested)
floors=$("$PY" - "$ROOT/pyproject.toml" <<'EOF'
import re, sys, tomllib
deps = tomllib.load(open(sys.argv[1], "rb"))["project"]["dependencies"]
for dep in deps:
    m = re.fullmatch(r"\s*([A-Za-z0-9_.\-]+)\s*>=\s*([0-9][0-9A-Za-z.]*)\s*(?:,.*)?", dep)
    if not m:
        sys.exit(f"oldest.sh: no lower bound to test in dependency {dep!r}")
    print(f"{m[1]}=={m[2]}", end=" ")
EOF
)
read -ra FLOORS <<<"$floors"
echo "oldest.sh: the floors: ${FLOORS[*]}"

t0=$SECONDS
"$PY" -m venv "$WORK/venv"
VPY="$WORK/venv/bin/python"
"$VPY" -m pip install --quiet --disable-pip-version-check "${FLOORS[@]}" "pytest>=8" "hypothesis>=6.100"
echo "oldest.sh: the floors installed in $((SECONDS - t0)) s"
t0=$SECONDS
# the build dir out of the checkout (pyproject's build-dir would write into it)
"$VPY" -m pip install --quiet --disable-pip-version-check "$ROOT" \
  --config-settings=build-dir="$WORK/build"
echo "oldest.sh: sjt-pin built and installed in $((SECONDS - t0)) s"

# nothing was moved off its floor by the install of the project
"$VPY" - "${FLOORS[@]}" <<'EOF'
import sys
from importlib.metadata import version
from packaging.version import Version
wrong = [f"{spec} (installed {version(spec.split('==')[0])})" for spec in sys.argv[1:]
         if Version(version(spec.split("==")[0])) != Version(spec.split("==")[1])]
assert not wrong, f"oldest.sh: not at the floor: {wrong}"
import numpy, pinocchio
print(f"oldest.sh: pin {pinocchio.__version__}, numpy {numpy.__version__}")
EOF
"$VPY" -m pip check --disable-pip-version-check

# the tests, from a copy of tests/ and pyproject.toml (pytest's config) with no sjt_pin beside
# them, so `import sjt_pin` finds the installed package
mkdir -p "$WORK/t"
tar -C "$ROOT" --exclude=__pycache__ --exclude=.hypothesis -cf - tests pyproject.toml \
  | tar -C "$WORK/t" -xf -
cd "$WORK/t"
files=() deselect=()
for t in "${TESTS[@]}"; do files+=("tests/$t.py"); done
for t in "${DESELECT[@]}"; do deselect+=(--deselect="tests/$t"); done
t0=$SECONDS
# the coverage options of addopts are left out (pytest-cov is a dev tool)
"$VPY" -m pytest -q -p no:cacheprovider -o addopts=-ra -m "not slow and not bench" \
  "${deselect[@]}" "$@" "${files[@]}"
echo "oldest.sh: pytest took $((SECONDS - t0)) s; OK in $((SECONDS - START)) s"
