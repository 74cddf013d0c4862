"""The ``recap`` commands load only what their work needs: reading runs never loads litellm or Ray,
and ``run``/``estimate`` load Ray, the gateway and DuckDB only once a sweep is accepted.

A fresh interpreter imports every command's module (what ``recap COMMAND`` does before its
work starts) and reports which of the heavy libraries came with them: litellm costs seconds of
CPU to import, Ray and DuckDB a good part of one, paid by every refusal and every ``recap sql``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[3]

_PROBE = """
import importlib, json, sys
HEAVY = ("litellm", "ray", "duckdb")
seen = {}
for name in sys.argv[1:]:
    importlib.import_module("pipeline.cli." + name)
    seen[name] = sorted(m for m in HEAVY if m in sys.modules)
print(json.dumps(seen))
"""


def test_command_modules_leave_the_heavy_libraries_to_the_work():
    # run, estimate, status and show first (nothing heavy), then the readers of runs (DuckDB only)
    names = ["run", "estimate", "status", "show", "sql", "report"]
    env = dict(os.environ, PYTHONPATH=str(REPO), LITELLM_LOCAL_MODEL_COST_MAP="True")
    r = subprocess.run([sys.executable, "-c", _PROBE, *names], capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout) == {
        "run": [],
        "estimate": [],
        "status": [],
        "show": [],
        "sql": ["duckdb"],
        "report": ["duckdb"],
    }
