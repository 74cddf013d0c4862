"""How long a 500-instance SWE-bench Verified sweep takes to be checked (and refused for missing
images) before anything runs, and how long ``recap data check`` takes on it.

Why: the issue's scale target is a preflight "in seconds" for the full 500: the image check is one
``docker images`` listing for all instances, never a container or a call per instance. The 500
records are synthetic (the dataset's schema, ids ``django__django-<n>``; nothing here reaches the
hub) and no image exists, so the sweep is refused - which is the path that must stay fast.

    .venv/bin/python bench/swe_preflight.py          # prints seconds for fetch --from, data check, run (refused)
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import sys
import tempfile
import time
from pathlib import Path

# the repository first: bench/pipeline.py would shadow the pipeline package
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pipeline.cli import main  # noqa: E402

N = 500


def _records(n: int) -> list[dict[str, str]]:
    return [
        {
            "repo": "django/django",
            "instance_id": f"django__django-{10000 + i}",
            "base_commit": "0" * 40,
            "patch": "diff --git a/x.py b/x.py\n",
            "test_patch": "diff --git a/tests/t.py b/tests/t.py\n",
            "problem_statement": f"issue {i}",
            "hints_text": "",
            "created_at": "2020-01-01T00:00:00Z",
            "version": "3.0",
            "FAIL_TO_PASS": json.dumps([f"test_{i} (t.Tests)"]),
            "PASS_TO_PASS": "[]",
            "environment_setup_commit": "0" * 40,
            "difficulty": "<15 min fix",
        }
        for i in range(n)
    ]


def _timed(argv: list[str]) -> tuple[float, int, str]:
    out, err = io.StringIO(), io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return time.perf_counter() - t0, code, (err.getvalue().strip().splitlines() or [""])[-1]


def run() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        src = root / "verified.jsonl"
        src.write_text("".join(json.dumps(r) + "\n" for r in _records(N)))
        data = root / "swebench-verified"
        s_fetch, code, _ = _timed(["data", "fetch", "swebench-verified", "--from", str(src), "--dest", str(data)])
        assert code == 0, "the synthetic file was refused"
        os.environ["SWEBENCH_VERIFIED_DATA"] = str(data)
        s_check, _, _ = _timed(["data", "check", "swebench-verified"])
        spec = root / "sweep.yaml"
        spec.write_text(
            f"run: bench\noutput: {root / 'run'}\nmodels: [{{model: offline/expert}}]\n"
            "methods: [{method: recap}, {method: mini_swe}]\n"
            "environments: [{benchmark: swe-verified, tasks: [all]}]\n"
        )
        s_run, code, line = _timed(["run", str(spec), "--progress", "off"])
        print(f"{N} instances x 2 methods = {2 * N} units")
        print(f"  data fetch --from (check + store): {s_fetch:.2f} s")
        print(f"  data check (records + one image listing): {s_check:.2f} s")
        print(f"  run, refused in preflight (exit {code}): {s_run:.2f} s")
        print(f"    {line[:160]}")


if __name__ == "__main__":
    run()
