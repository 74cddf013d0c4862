#!/usr/bin/env bash
# The README's main job: install the project, run the demo sweep on a local Ray cluster
# (ReCAP and ReAct on a few Robotouille and ALFWorld instances, offline expert TEST DOUBLE with
# error injection), print the summary table and write the report.
#
#   bash scripts/demo.sh                 # output in runs/demo (a second call finds it complete)
#   DEMO_OUT=runs/demo2 bash scripts/demo.sh
#
# Environment: ROBOTOUILLE_DATA / ALFWORLD_DATA (default: `recap data list`'s look-up), PYTHON (default
# python3, 3.11+), RECAP_SKIP_INSTALL=1 to use the current .venv as it is.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT="$(pwd)"

if [ "${RECAP_SKIP_INSTALL:-0}" != "1" ]; then
  bash scripts/setup_venv.sh "alfworld,test,swe"   # the same environment as the test command
fi

export LITELLM_LOCAL_MODEL_COST_MAP=True
export RAY_USAGE_STATS_ENABLED=0
# data folders: ROBOTOUILLE_DATA / ALFWORLD_DATA when set, else the same look-up as every recap
# command (`recap data list`: upstream caches, ~/.cache/recap-eval/data, ../shared/data)
OUT="${DEMO_OUT:-runs/demo}"

# the console script when installed, else the module (RECAP_SKIP_INSTALL on a bare checkout)
if [ -x .venv/bin/recap ]; then RECAP=(.venv/bin/recap); else RECAP=(env PYTHONPATH="$ROOT" .venv/bin/python -m pipeline.cli); fi

# the demo sweep for the data this machine has (a benchmark without data is left out, with a
# line saying how to fetch it)
mkdir -p "$(dirname "$OUT")"
SPEC="$(dirname "$OUT")/.demo-sweep.yaml"
PYTHONPATH="$ROOT" .venv/bin/python scripts/demo_spec.py examples/demo.yaml "$SPEC"

status=0
"${RECAP[@]}" run "$SPEC" --output "$OUT" || status=$?
if [ "$status" -ne 0 ] && [ "$status" -ne 3 ]; then
  echo "demo sweep failed (exit $status)" >&2
  exit "$status"
fi
"${RECAP[@]}" report "$OUT"
echo
echo "The recap command lives in .venv: run 'source .venv/bin/activate' first, or call .venv/bin/recap."
echo "  status:  .venv/bin/recap status $OUT"
echo "  query:   .venv/bin/recap sql $OUT \"select arm, count(*) units, avg(success::int) success from terminal group by 1\""
echo "  report:  $OUT/report/ (spend shown for offline/* models is nominal: they are test doubles)"
exit "$status"
