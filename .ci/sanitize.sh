#!/usr/bin/env bash
# CI job "sanitize": the kernels built with AddressSanitizer and UndefinedBehaviorSanitizer
# (CMakeLists.txt's SJT_SANITIZE), installed in their own environment, run the tests of the
# compiled boundary: the kernels and their argument fuzz, the constraint stage, collision,
# copies, bad input. Any report aborts the run (halt_on_error), so a green job is zero reports.
# Run from the repository root after .ci/run's quick start: it reuses .venv's packages (its
# site-packages on the path of a new venv that holds only the sanitized sjt-pin, not the
# editable one). Every file it makes is under one temp dir. Env: PYTHON (default .venv's).
set -euo pipefail
ROOT=$PWD
PY=${PYTHON:-$ROOT/.venv/bin/python}
[[ -f "$ROOT/pyproject.toml" && -x "$PY" ]] || { echo "sanitize.sh: run me from the repo root after .ci/run's install" >&2; exit 2; }
WORK=$(mktemp -d /tmp/ci-sanitize.XXXXXX)
START=$SECONDS
trap 'rc=$?; if ((rc == 0)); then rm -rf "$WORK"; else echo "sanitize.sh: FAILED (rc=$rc), logs kept in $WORK" >&2; fi' EXIT

# 1. the sanitized wheel (its own build dir, out of the checkout)
t0=$SECONDS
"$PY" -m pip wheel "$ROOT" --no-deps -q -w "$WORK/dist" --config-settings=build-dir="$WORK/build" \
  --config-settings=cmake.define.SJT_SANITIZE=ON >"$WORK/build.log" 2>&1 \
  || { tail -n 60 "$WORK/build.log" >&2; exit 1; }
echo "sanitize.sh: the ASan + UBSan build took $((SECONDS - t0)) s"

# 2. a venv with that wheel alone, .venv's packages beside it: their folder on the path (a .pth
#    file named to come first) and their .pth files (cmeel's, which puts Pinocchio on the path),
#    but the editable install's hook
"$PY" -m venv --without-pip "$WORK/venv"
VPY="$WORK/venv/bin/python"
site=$("$VPY" -c "import sysconfig; print(sysconfig.get_paths()['purelib'])")
deps=$("$PY" -c "import sysconfig; print(sysconfig.get_paths()['purelib'])")
echo "$deps" >"$site/00-ci-deps.pth"
for pth in "$deps"/*.pth; do
  [[ $(basename "$pth") == _editable* ]] || cp "$pth" "$site/"
done
"$PY" -m zipfile -e "$WORK"/dist/sjt_pin-*.whl "$site"  # (a wheel is a zip of site-packages)

# 3. the tests, from a copy outside the checkout (import sjt_pin finds the sanitized one); no
#    file with a browser page (Chromium would inherit the preloaded ASan runtime)
mkdir -p "$WORK/t"
tar -C "$ROOT" --exclude=__pycache__ -cf - tests pyproject.toml | tar -C "$WORK/t" -xf -
cd "$WORK/t"
# ASan's runtime first, and libstdc++ loaded before it intercepts __cxa_throw (python is no
# C++ program: without it the first C++ exception aborts in ASan's interceptor); the runtimes
# of the g++ that built the kernels, preloaded into the python commands alone
asan=$(g++ -print-file-name=libasan.so) stdcxx=$(g++ -print-file-name=libstdc++.so)
[[ -f $asan && -f $stdcxx ]] || { echo "sanitize.sh: no libasan/libstdc++ of g++ ($asan, $stdcxx)" >&2; exit 2; }
preload="$asan $stdcxx"
export ASAN_OPTIONS=detect_leaks=0:halt_on_error=1:abort_on_error=1
export UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1
LD_PRELOAD=$preload "$VPY" -c "import sjt_pin.kernels._core as c, sys; assert c.__file__.startswith('$site'), c.__file__"
t0=$SECONDS rc=0
LD_PRELOAD=$preload "$VPY" -m pytest -p no:cacheprovider -o "addopts=-ra" -m "not slow" -q -x -s \
  tests/test_kernels.py tests/test_constraints.py tests/test_decrease.py tests/test_copies.py \
  tests/test_bad_input.py tests/test_boundary_collision.py tests/test_boundary_search.py \
  tests/test_collision_moving.py tests/test_collision_trees.py tests/test_whole_body.py \
  tests/test_warm_start.py "tests/test_range_minimum.py::test_a_target_beyond_a_range_ends_at_rest_on_the_constrained_minimum[ur5-0-sjt-True]" \
  "tests/test_range_minimum.py::test_a_target_beyond_a_range_ends_at_rest_on_the_constrained_minimum[panda-7-dls-False]" \
  >"$WORK/pytest.log" 2>&1 || rc=$?
if ((rc != 0)) || grep -q -E "ERROR: AddressSanitizer|runtime error:" "$WORK/pytest.log"; then
  echo "!!! sanitize.sh: pytest failed or a sanitizer reported (rc=$rc):" >&2
  grep -n -A30 -E "ERROR: AddressSanitizer|runtime error:" "$WORK/pytest.log" | head -n 80 >&2 || true
  tail -n 40 "$WORK/pytest.log" >&2
  exit 1
fi
tail -n 1 "$WORK/pytest.log"
echo "sanitize.sh: OK, zero sanitizer reports in $((SECONDS - t0)) s of tests, $((SECONDS - START)) s in all"
