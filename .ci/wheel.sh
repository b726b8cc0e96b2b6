#!/usr/bin/env bash
# CI job "wheel": a wheel built by the project's own command installs into a fresh environment
# with no compiler on PATH and passes the tests run against the installed wheel (not ./sjt_pin).
# By default it runs the slow tests (-m "slow and not bench"): .ci/run runs the quick suite in
# the quick start's editable environment and leaves the slow ones to this job, so each test runs
# once. WHEEL_MARKS="not bench" runs the whole suite against the wheel instead.
# Run from the repository root. Reads the checkout only: every file it makes is under one temp
# dir (removed on success, kept and named on failure). Env: PYTHON (default python3),
# WHEEL_MARKS (pytest's -m). Extra arguments go to pytest (e.g. --deselect NODE).
set -euo pipefail
ROOT=$PWD
PY=${PYTHON:-python3}
MARKS=${WHEEL_MARKS:-slow and not bench}
[[ -f "$ROOT/pyproject.toml" && -d "$ROOT/sjt_pin" ]] || { echo "wheel.sh: run me from the repo root" >&2; exit 2; }
WORK=$(mktemp -d /tmp/ci-wheel.XXXXXX)
START=$SECONDS
trap 'rc=$?; if ((rc == 0)); then rm -rf "$WORK"; else echo "wheel.sh: FAILED (rc=$rc), logs kept in $WORK" >&2; fi' EXIT

# run a step with its output in $WORK/NAME.log; on failure show the log's tail and stop
step() {
  local name=$1 t0=$SECONDS; shift
  if ! "$@" >"$WORK/$name.log" 2>&1; then
    echo "!!! wheel.sh: step '$name' failed after $((SECONDS - t0)) s: $*" >&2
    echo "!!! the last 80 lines of $WORK/$name.log:" >&2
    tail -n 80 "$WORK/$name.log" >&2
    exit 1
  fi
  echo "wheel.sh: $name took $((SECONDS - t0)) s"
}

# the checkout's files, ignored ones included, before the job: nothing may be added or changed
checkout_state() { git -C "$ROOT" status --porcelain --ignored --untracked-files=all 2>/dev/null || true; }
checkout_state >"$WORK/checkout.before"

# tests that need the repository's own sources, which neither a wheel nor the copy below
# carries. A file is left out whole, a node by its id.
EXCLUDE=(
  # builds a wheel of the checkout (step 'contents' below checks this job's wheel the same way)
  test_packaging.py::test_wheel_ships_planar3_urdf_and_generator
  test_readme.py::test_ci_runs_the_readme_quick_start_in_order  # reads .ci/run
  test_urdf_errors.py::test_bytes_path_and_text_give_the_same_robot  # reads robots/planar3.urdf
  test_urdf_errors.py::test_single_package_dir_is_one_folder  # robots/ as a package dir
  test_urdf_errors.py::test_paper_planar3_urdf_passes_the_checks  # reads robots/planar3.urdf
)

# 1. the wheel, by the project's own command, with build isolation (the build dir is moved out
#    of the checkout: pyproject's build-dir = "build/{wheel_tag}" would write into it)
step build "$PY" -m pip wheel "$ROOT" --no-deps -w "$WORK/dist" \
  --config-settings=build-dir="$WORK/build"
wheels=("$WORK"/dist/sjt_pin-*.whl)
[[ ${#wheels[@]} -eq 1 && -f ${wheels[0]} ]] || { echo "!!! wheel.sh: expected one wheel in $WORK/dist" >&2; ls "$WORK/dist" >&2; exit 1; }
WHEEL=${wheels[0]}

# 2. what the wheel holds (tests/test_packaging.py's checks, on this wheel): the generated URDF
#    and its generator, the type marker, every package of the source tree, the compiled kernels,
#    the licence, and no kernel source, cache or test
step contents "$PY" - "$WHEEL" "$ROOT" <<'EOF'
import sys, zipfile
from pathlib import Path
wheel, root = sys.argv[1], Path(sys.argv[2])
names = zipfile.ZipFile(wheel).namelist()
packages = {str(p.parent.relative_to(root)) for p in (root / "sjt_pin").rglob("__init__.py")}
missing = [f"{p}/__init__.py" for p in sorted(packages) if f"{p}/__init__.py" not in names]
missing += [n for n in ["sjt_pin/robots/planar3.urdf", "sjt_pin/robots/planar3.py",
                        "sjt_pin/py.typed"] if n not in names]
assert not missing, f"missing from the wheel: {missing}"
assert any(n.startswith("sjt_pin/kernels/_core.") for n in names), "no compiled kernels"
assert any(n.endswith("LICENSE") for n in names), "no LICENSE"
extra = [n for n in names if "__pycache__" in n or n.startswith(("tests/", "sjt_pin/kernels/src/"))]
assert not extra, f"in the wheel but should not be: {extra}"
print(len(names), "files")
EOF

# 3. no compiler from here on: shims that fail loudly, CC/CXX pointing nowhere
mkdir -p "$WORK/nocc"
for c in gcc cc g++ c++ clang clang++; do
  printf '#!/bin/sh\necho "no compiler here" >&2\nexit 1\n' >"$WORK/nocc/$c"
  chmod +x "$WORK/nocc/$c"
done
export PATH="$WORK/nocc:$PATH" CC="$WORK/no/such/cc" CXX="$WORK/no/such/c++"
if g++ --version >/dev/null 2>&1 || cc --version >/dev/null 2>&1; then
  echo "!!! wheel.sh: a compiler is still reachable" >&2; exit 1
fi

# 4. a fresh venv, the wheel with its test extras
step venv "$PY" -m venv "$WORK/venv"
VPY="$WORK/venv/bin/python"
step pip "$VPY" -m pip install --upgrade pip
step install "$VPY" -m pip install "$WHEEL[dev]"
cd "$WORK"  # not the checkout: python -c puts the cwd first on sys.path
step import "$VPY" -c "
import sjt_pin, sjt_pin.kernels._core as c, sys
assert sjt_pin.__file__.startswith(sys.prefix) and c.__file__.startswith(sys.prefix), c.__file__
r = sjt_pin.Robot.planar3()  # the URDF, package data of the wheel
assert r.nq == 3 and str(r.urdf).startswith(sys.prefix), r.urdf
print(sjt_pin.__file__, c.__file__, r.urdf)"

# 5. the tests, from a copy of tests/ + pyproject.toml (pytest's config) and of the files they
#    read (README.md, docs/, notebooks/) with no sjt_pin beside them, so `import sjt_pin` finds
#    the installed wheel
mkdir -p "$WORK/t"
tar -C "$ROOT" --exclude=__pycache__ --exclude=.pytest_cache --exclude=.hypothesis \
  --exclude=docs/_build --exclude=docs/api/generated --exclude=.ipynb_checkpoints \
  -cf - tests pyproject.toml README.md docs notebooks | tar -C "$WORK/t" -xf -
deselect=()
for t in "${EXCLUDE[@]}"; do
  if [[ $t == *::* ]]; then deselect+=(--deselect="tests/$t"); else deselect+=(--ignore="tests/$t"); fi
done
cd "$WORK/t"
# the venv's scripts first (as if activated: under .ci/run, .venv's editable sjt-pin is on PATH)
export PATH="$WORK/venv/bin:$PATH" VIRTUAL_ENV="$WORK/venv"
# the coverage options of addopts are left out (-o addopts)
t0=$SECONDS rc=0
"$VPY" -m pytest -p no:cacheprovider -o "addopts=-ra" -m "$MARKS" -q \
  "${deselect[@]}" "$@" tests >"$WORK/pytest.log" 2>&1 || rc=$?
if ((rc != 0)); then
  echo "!!! wheel.sh: pytest -m '$MARKS' failed (rc=$rc; 5: no test selected)" >&2
  sed -n '/= FAILURES =\|= ERRORS =\|short test summary/,$p' "$WORK/pytest.log" | tail -n 200 >&2
  tail -n 3 "$WORK/pytest.log" >&2
  exit 1
fi
grep '^SKIPPED' "$WORK/pytest.log" || true  # the skips (-ra's summary), loudly
tail -n 1 "$WORK/pytest.log"  # pytest's closing line
echo "wheel.sh: pytest -m '$MARKS' took $((SECONDS - t0)) s"

cd "$ROOT"
checkout_state >"$WORK/checkout.after"
if ! diff "$WORK/checkout.before" "$WORK/checkout.after" >"$WORK/checkout.diff"; then
  echo "!!! wheel.sh: the job changed the checkout:" >&2
  cat "$WORK/checkout.diff" >&2
  exit 1
fi
echo "wheel.sh: OK, $(basename "$WHEEL") installed and tested without a compiler (${#EXCLUDE[@]} tests that need the sources left out), $((SECONDS - START)) s"
