"""Through the pipeline (a real local Ray, the offline expert, a local sandbox): a ReCAP episode
that reaches its command limit with the fix made hands the diff in, and the run's tables say so:
the episode row ends ``autosubmitted`` with the limit in its error and success the verdict, and
one ``evaluations`` row judges the diff (issue 34)."""

from __future__ import annotations

import pytest

from pipeline.driver import Driver, prepare
from pipeline.gateway_backend import make_backend
from pipeline.spec import parse_spec
from pipeline.sqlview import open_tables
from pipeline.store import RunStore
from workers.envs.swe.examples import make_fixtures

SPEC = """run: {name}
output: {out}
models:
  - model: offline/expert
methods:
  - method: recap
    profile: paper
environments:
  - benchmark: swe
    tasks: [all]
    options: {{instances_file: "{tasks}", sandbox: local, max_commands: 2, grading: ours}}
workers: 1
"""


@pytest.mark.slow  # a Ray run with a sandboxed episode and its grading: over a minute on a small machine
def test_a_command_limit_with_the_fix_made_is_graded_and_the_row_says_autosubmitted(ray_address, tmp_path):
    fixtures = make_fixtures(tmp_path / "fixtures", ("format",))
    out = tmp_path / "run"
    text = SPEC.format(name=out.name, out=out, tasks=fixtures.tasks_file)
    spec = parse_spec(text, "sweep.yaml")
    summary = Driver(prepare(spec, text), make_backend(spec), progress="off").run()
    assert (summary.total, summary.finished_now, summary.exit_code()) == (1, 1, 0)
    con, _ = open_tables(RunStore(out))
    rows = con.execute("select end_reason, success, error, steps from episodes").fetchall()
    assert rows == [("autosubmitted", True, "step_cap: 2 steps (cap 2)", 2)]
    evals = con.execute("select resolved, reason, grading, patch like '%cents / 100:.2f%' from evaluations").fetchall()
    assert evals == [(True, "resolved", "ours", True)]
    calls = con.execute("select name from tool_calls order by index").fetchall()
    assert calls == [("view",), ("str_replace",)]
