#!/usr/bin/env bash
# The test command (README, .ci/run): sets up .venv and runs the default suite.
#   bash scripts/test.sh          default suite (everything not marked slow/realmodel)
#   bash scripts/test.sh slow     the slow suites (all 134 ALFWorld games x 2 versions, two-node Ray, ...)
# pytest's exit code 5 (no tests collected) is a failure here.
set -uo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup_venv.sh "alfworld,test" || exit 1
# the report's browser check renders the HTML in headless Chromium (a Debian package)
if ! command -v chromium >/dev/null 2>&1 && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
  echo "installing chromium for the report screenshot test"
  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium) >/dev/null 2>&1 || echo "chromium could not be installed; the browser test will be skipped" >&2
fi
export LITELLM_LOCAL_MODEL_COST_MAP=True
export RAY_USAGE_STATS_ENABLED=0
marker="not slow and not realmodel"
if [ "${1:-}" = "slow" ]; then marker="slow"; shift; fi
.venv/bin/python -m pytest -m "$marker" -q "$@"
rc=$?
if [ $rc -eq 5 ]; then echo "no tests were collected: failing" >&2; exit 1; fi
exit $rc
