#!/usr/bin/env bash
# Builds the coding sandbox's Docker image (recap-eval/sandbox:py311: Python 3.11, pytest, git, GNU
# patch) from the Debian mirror with debootstrap + docker import (no registry needed). Idempotent:
# does nothing if the image exists and was built from the current recipe (its label
# org.recap-eval.sandbox.recipe); one built from an older recipe is rebuilt.
#   bash scripts/build_sandbox_image.sh [--tag TAG] [--force]
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v debootstrap >/dev/null 2>&1; then
  if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null 2>&1; then
    echo "error: debootstrap is missing and cannot be installed here (needs root and apt-get)" >&2
    exit 1
  fi
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq debootstrap >/dev/null
fi
PY=${PYTHON:-.venv/bin/python}
[ -x "$PY" ] || PY=python3
PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" exec "$PY" -m workers.sandbox.image "$@"
