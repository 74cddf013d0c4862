#!/usr/bin/env bash
# The test command (README, .ci/run): sets up .venv and runs the default suite.
#   bash scripts/test.sh          default suite (everything not marked slow/realmodel/docker), then
#                                 the Docker sandbox tests (marker docker; they start Docker if needed)
#   bash scripts/test.sh slow     the slow suites (all 134 ALFWorld games x 2 versions, two-node Ray, ...),
#                                 then the real-model slow test (a sweep serving SmolLM2-135M with llama.cpp
#                                 through Ray Serve) by scripts/realmodel.sh, which installs llama-cpp-python
#                                 (a compile of llama.cpp the first time) and the weights;
#                                 RECAP_SKIP_REALMODEL=1 skips it
# pytest's exit code 5 (no tests collected) is a failure here.
set -uo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup_venv.sh "alfworld,test,swe" || exit 1
# The report's browser check (tests/reports/test_browser.py, default suite) renders the HTML in
# the distribution's headless Chromium; nothing is downloaded at run time. Without a Chromium
# that test fails; RECAP_SKIP_BROWSER=1 is the explicit opt-out (the test is then skipped).
has_chromium() { command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1 || command -v google-chrome >/dev/null 2>&1; }
has_bwrap() { command -v bwrap >/dev/null 2>&1; }
# need PACKAGE CHECK SKIP_VAR WHAT: install the distribution's PACKAGE (apt, as root) unless CHECK
# passes or SKIP_VAR=1 says to skip the tests that need it; otherwise fail with the two ways out.
need() {
  local package=$1 check=$2 skip=$3 what=$4 log
  if [ "${!skip:-}" = 1 ]; then
    echo "$skip=1: skipping $what" >&2
    return 0
  fi
  "$check" && return 0
  if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null 2>&1; then
    echo "error: no $package, and it cannot be installed here (needs root and apt-get)." >&2
    echo "  install it (sudo apt-get install -y $package) or set $skip=1 to skip $what" >&2
    exit 1
  fi
  echo "installing $package (apt) for $what"
  log=$(mktemp)
  if ! { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$package"; } >"$log" 2>&1 || ! "$check"; then
    tail -n 20 "$log" >&2
    echo "error: apt-get could not install $package (output above)." >&2
    echo "  fix the package source, or set $skip=1 to skip $what" >&2
    rm -f "$log"
    exit 1
  fi
  rm -f "$log"
}
need chromium has_chromium RECAP_SKIP_BROWSER "the report's headless-browser check"
# The local sandbox confines each command with bubblewrap (workers/sandbox/bwrap.py); its tests
# (tests/workers/sandbox/test_local_bwrap*.py, and every test opening a local sandbox) fail without
# it. RECAP_SKIP_BWRAP=1 is the explicit opt-out (the bubblewrap tests are then skipped; the other
# local-sandbox tests run it with sandbox_trust: none).
need bubblewrap has_bwrap RECAP_SKIP_BWRAP "the bubblewrap sandbox tests"
export LITELLM_LOCAL_MODEL_COST_MAP=True
export RAY_USAGE_STATS_ENABLED=0
# pytest keeps each test module's assertion-rewritten bytecode in __pycache__ (gitignored): with it a
# test process collects the suite in ~7 s of CPU instead of ~16 s (the rewrite of 300 test modules),
# and every pytest process after the first (each xdist worker, each phase) reads it. An environment
# with PYTHONDONTWRITEBYTECODE=1 would make every process rewrite them all again.
unset PYTHONDONTWRITEBYTECODE
marker="not slow and not realmodel and not docker"
phase=default
# the slow suites that need a real model (marker realmodel) run after them, by scripts/realmodel.sh
if [ "${1:-}" = "slow" ]; then marker="slow and not realmodel"; phase=slow; shift; fi
# the habits (pyproject.toml [tool.ruff], [tool.mypy]): lint, format and types, before the tests
lint=0
.venv/bin/ruff check . || { echo "ruff check: findings above (ruff check --fix fixes the marked ones)" >&2; lint=1; }
.venv/bin/ruff format --check . >/dev/null || { .venv/bin/ruff format --check . >&2; echo "ruff format: run '.venv/bin/ruff format .'" >&2; lint=1; }
# mypy: from a clean checkout it reads Ray's, litellm's and openai's sources (~50 s of one core).
# Before the default suite it type-checks in the background while the tests run (much of their time
# is spent waiting on Ray actors and processes); its verdict is read after that phase. Before the
# slow suites (chaos timings) it runs first, alone.
mypy_log=$(mktemp)
if [ "$phase" = default ]; then
  .venv/bin/mypy >"$mypy_log" 2>&1 &
  mypy_pid=$!
else
  .venv/bin/mypy >"$mypy_log" 2>&1
  mypy_rc=$?
fi
# pytest-xdist: the default suite runs in RECAP_TEST_WORKERS processes (default: one per core, at
# least 2: much of a Ray test is waiting on actors and processes). Each worker has its own Ray
# cluster (tests/conftest.py, ray_address); --dist loadgroup keeps the tests that read one shared
# run (xdist_group) on one worker, so that run is made once. The slow suites (chaos timings, two
# Ray nodes) stay in one process unless RECAP_TEST_WORKERS says otherwise.
cores=$(nproc 2>/dev/null || echo 2)
if [ "$phase" = slow ]; then workers="${RECAP_TEST_WORKERS:-0}"; else workers="${RECAP_TEST_WORKERS:-$((cores < 2 ? 2 : cores))}"; fi
.venv/bin/python -m pytest -m "$marker" -q --durations=15 -n "$workers" --dist loadgroup "$@"
rc=$?
if [ "$phase" = default ]; then wait "$mypy_pid"; mypy_rc=$?; fi
if [ "$mypy_rc" -ne 0 ]; then cat "$mypy_log" >&2; echo "mypy: type errors above" >&2; lint=1; fi
rm -f "$mypy_log"
if [ $rc -eq 5 ]; then echo "no tests were collected: failing" >&2; exit 1; fi
# the real-model slow test (tests/realmodel/test_served_llama_cpp.py): llama.cpp served by the sweep
if [ "$phase" = slow ] && [ $# -eq 0 ]; then
  if [ "${RECAP_SKIP_REALMODEL:-}" = 1 ]; then
    echo "RECAP_SKIP_REALMODEL=1: the real-model slow test (llama.cpp served by the sweep) is skipped" >&2
  else
    bash scripts/realmodel.sh -m "realmodel and slow" --durations=5
    mrc=$?
    if [ $mrc -eq 5 ]; then echo "no real-model slow test was collected: failing" >&2; mrc=1; fi
    if [ $rc -eq 0 ]; then rc=$mrc; fi
  fi
fi
# the Docker sandbox tests (marker docker), after the default suite: they need a Docker engine
# (scripts/docker_up.sh installs and starts one where we are root with apt-get) and the sandbox
# image, built locally from the Debian mirror (scripts/build_sandbox_image.sh: ~2 min, once per
# machine). RECAP_SKIP_DOCKER=1 is the explicit opt-out; without it, no Docker is a failure.
if [ "$phase" = default ] && [ $# -eq 0 ]; then
  if [ "${RECAP_SKIP_DOCKER:-}" = 1 ]; then
    echo "RECAP_SKIP_DOCKER=1: the Docker sandbox tests are skipped" >&2
  elif ! bash scripts/docker_up.sh || ! bash scripts/build_sandbox_image.sh; then
    echo "error: the Docker sandbox tests need a Docker engine and the sandbox image (above); RECAP_SKIP_DOCKER=1 skips them" >&2
    rc=1
  else
    # two passes: the tests that load the host on purpose (marker host_load: fork bombs, CPU-bound
    # commands killed at their timeout, disks filled to their cap) run alone in one process, since
    # sweeps beside them would time out for the wrong reason; the rest (containers started, commands
    # run, sweeps through Docker: mostly waiting on the Docker daemon) in RECAP_TEST_WORKERS processes
    # each pass collects only the test files that name the docker marker (and the folders of the
    # conftest files that parametrise fixtures with it), not the whole suite again: a collection of
    # the suite is ~7 s of CPU in each of the three processes, of these files ~2 s (the same tests:
    # `pytest --collect-only -m docker` lists the same ids either way). Nothing found: the whole suite.
    docker_paths=$( (grep -rlE 'mark\.docker' tests --include='test_*.py'; grep -rlE 'mark\.docker' tests --include=conftest.py | xargs -r -n1 dirname) | sort -u)
    [ -n "$docker_paths" ] || docker_paths=tests
    # shellcheck disable=SC2086 # one path a word (no spaces in the test paths)
    .venv/bin/python -m pytest -m "docker and not host_load and not slow and not realmodel" -q --durations=5 -n "$workers" --dist loadgroup $docker_paths
    drc=$?
    # shellcheck disable=SC2086
    .venv/bin/python -m pytest -m "docker and host_load and not slow and not realmodel" -q --durations=5 -n 0 $docker_paths
    hrc=$?
    if [ $drc -eq 5 ] || [ $hrc -eq 5 ]; then echo "no Docker sandbox tests were collected in one of the two passes: failing" >&2; drc=1; fi
    if [ $drc -eq 0 ]; then drc=$hrc; fi
    if [ $rc -eq 0 ]; then rc=$drc; fi
  fi
fi
if [ $rc -eq 0 ] && [ $lint -ne 0 ]; then echo "tests passed, but lint/format/type checks failed (above)" >&2; exit 1; fi
exit $rc
