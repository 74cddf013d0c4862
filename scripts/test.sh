#!/usr/bin/env bash
# The test command (README, .ci/run): sets up .venv and runs the default suite.
#   bash scripts/test.sh          default suite (everything not marked slow/realmodel)
#   bash scripts/test.sh slow     the slow suites (all 134 ALFWorld games x 2 versions, two-node Ray, ...)
# pytest's exit code 5 (no tests collected) is a failure here.
set -uo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup_venv.sh "alfworld,test" || exit 1
export LITELLM_LOCAL_MODEL_COST_MAP=True
export RAY_USAGE_STATS_ENABLED=0
marker="not slow and not realmodel"
if [ "${1:-}" = "slow" ]; then marker="slow"; shift; fi
.venv/bin/python -m pytest -m "$marker" -q "$@"
rc=$?
if [ $rc -eq 5 ]; then echo "no tests were collected: failing" >&2; exit 1; fi
exit $rc
