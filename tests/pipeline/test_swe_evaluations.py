"""A coding sweep on a real (local) Ray writes one ``evaluations`` row per judged episode, graded
by ours and by the official harness, readable through ``recap sql``."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from pipeline.driver import Driver, prepare
from pipeline.gateway_backend import make_backend
from pipeline.spec import parse_spec
from workers.envs.swe.examples import make_fixtures

pytest.importorskip("swebench.harness.grading", reason="the official grading needs the swebench package (extra swe)")

SPEC = """run: {name}
output: {out}
models:
  - model: offline/expert
methods:
  - method: react
    profile: paper
environments:
  - benchmark: swe
    tasks: [all]
    options: {{instances_file: "{tasks}", sandbox: local}}
workers: 2
"""

ROOT = Path(__file__).resolve().parents[2]
QUERY = """select e.instance_id, e.resolved, e.reason, e.graded_by, e.grading, e.ours_resolved, e.official_resolved,
  e.official_status, e.official_parser, e.tests, e.fail_to_pass_passed, e.fail_to_pass_total, e.pass_to_pass_passed,
  e.pass_to_pass_total, e.patch_bytes = octet_length(e.patch::blob) as bytes_ok, e.log like '%PASSED%' as has_summary,
  e.duration_s > 0 as timed, p.success
from evaluations e join episodes p using (episode_id) order by e.instance_id"""


def test_a_sweep_writes_its_evaluations_and_recap_sql_reads_them(ray_address, tmp_path):
    fixtures = make_fixtures(tmp_path / "fixtures", ("offbyone", "p2p"))
    out = tmp_path / "run"
    text = SPEC.format(name=out.name, out=out, tasks=fixtures.tasks_file)
    spec = parse_spec(text, "sweep.yaml")
    summary = Driver(prepare(spec, text), make_backend(spec), progress="off").run()
    assert (summary.total, summary.finished_now, summary.exit_code()) == (2, 2, 0)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "LITELLM_LOCAL_MODEL_COST_MAP": "True", "RAY_USAGE_STATS_ENABLED": "0"}
    done = subprocess.run(
        [sys.executable, "-m", "pipeline.cli", "sql", str(out), QUERY, "--json"],
        capture_output=True,
        text=True,
        env=env,
        cwd=ROOT,
        timeout=120,
    )
    assert (done.returncode, done.stderr) == (0, "")
    base = {
        "resolved": True,
        "reason": "resolved",
        "graded_by": "official",
        "grading": "both",
        "ours_resolved": True,
        "official_resolved": True,
        "official_status": "RESOLVED_FULL",
        "official_parser": "parse_log_pytest",
        "bytes_ok": True,
        "has_summary": True,
        "timed": True,
        "success": True,
    }
    rows = json.loads(done.stdout)
    assert rows == [
        {
            **base,
            "instance_id": "swe/fixture__offbyone-1",
            "tests": json.dumps(
                {
                    "tests/test_mathutil.py::test_count_range_inclusive": "PASSED",
                    "tests/test_mathutil.py::test_total": "PASSED",
                },
                sort_keys=True,
            ),
            "fail_to_pass_passed": 1,
            "fail_to_pass_total": 1,
            "pass_to_pass_passed": 1,
            "pass_to_pass_total": 1,
        },
        {
            **base,
            "instance_id": "swe/fixture__p2p-1",
            "tests": json.dumps(
                {
                    "tests/test_flags.py::test_empty": "PASSED",
                    "tests/test_flags.py::test_false": "PASSED",
                    "tests/test_flags.py::test_variants": "PASSED",
                },
                sort_keys=True,
            ),
            "fail_to_pass_passed": 1,
            "fail_to_pass_total": 1,
            "pass_to_pass_passed": 2,
            "pass_to_pass_total": 2,
        },
    ]
