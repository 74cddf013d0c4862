"""The report over a run the pipeline wrote (tests/reports/pipeline_run.py): the rows have the
shape of schema version 2, and every report table equals what Python recomputes from the run's
own Parquet rows; ``recap status`` and the report's coverage table give the same numbers."""

from __future__ import annotations

import json
from collections import defaultdict
from typing import Any

import pytest

from pipeline.store import RunStore
from pipeline.summary import collect
from recap.methods import METHODS
from reports.build import build_report
from reports.views import named_query, open_runs
from schemas.labels import ALFWORLD_TASK_TYPES
from schemas.parts import read_table

TD = "expert (test double)"


@pytest.fixture(scope="module")
def run(pipeline_run) -> dict[str, Any]:
    out, code, killed = pipeline_run
    rows = read_table(out, "episodes")[0].to_pylist()
    plan = json.loads((out / "plan.json").read_text())["units"]
    return {"out": out, "code": code, "killed": killed["unit"], "rows": rows, "plan": plan}


def _unit_rows(rows: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Each unit's counted row, by the rule written out here: its latest finished attempt
    (neither budget_exhausted nor infra_error), else its latest attempt."""
    out: dict[str, dict[str, Any]] = {}
    for r in sorted(rows, key=lambda r: r["attempt"]):
        fin = r["end_reason"] not in ("budget_exhausted", "infra_error")
        prev = out.get(r["unit_id"])
        prev_fin = prev is not None and prev["end_reason"] not in ("budget_exhausted", "infra_error")
        if prev is None or fin or not prev_fin:
            out[r["unit_id"]] = r
    return out


def _finished(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [r for r in _unit_rows(rows).values() if r["end_reason"] not in ("budget_exhausted", "infra_error")]


def test_the_run_hit_its_cap_and_lost_a_worker(run):
    rows, killed = run["rows"], run["killed"]
    assert run["code"] == 4  # a unit ended in an infrastructure failure
    reasons = {r["end_reason"] for r in rows}
    assert "budget_exhausted" in reasons and "infra_error" in reasons
    assert len({r["unit_id"] for r in rows}) < len(run["plan"])  # some units never started
    gave_up = [r for r in rows if r["unit_id"] == killed]
    assert len(gave_up) == 1 and gave_up[0]["end_reason"] == "infra_error"
    assert gave_up[0]["error"].startswith("gave up after 1 failed attempts (infrastructure: worker_lost); last: ")


def test_rows_have_the_version_2_shape(run):
    rows, plan = run["rows"], {u["unit_id"]: u for u in run["plan"]}
    for r in rows:
        u = plan[r["unit_id"]]
        assert r["method"] in METHODS and r["method"] == u["method_name"]
        assert r["label"] == u["method"]
        assert (r["label"], r["method"], r["ablation"], r["profile"]) in {
            ("recap", "recap", None, None),
            ("react", "react", None, None),
            ("recap-no-think", "recap", "no_think", None),
        }
        assert (r["model"], r["provider_model"], r["test_double"]) == ("expert", "offline/expert", True)
        parts = r["instance_id"].split("/")
        if r["benchmark"] == "alfworld":
            assert (r["split"], r["task"]) == ("valid_unseen", parts[1]) and r["task"] in ALFWORLD_TASK_TYPES
        else:
            assert (r["benchmark"], r["split"], r["task"]) == ("robotouille", parts[1], parts[2].split("@")[0])


def test_the_gave_up_row_keeps_its_place_and_its_spend(run):
    row = next(r for r in run["rows"] if r["unit_id"] == run["killed"])
    parts = row["instance_id"].split("/")
    assert row["split"] == ("valid_unseen" if parts[0] == "alfworld" else parts[1]) and row["task"]
    # its spend is what the ledger journal settled for its episode id, recomputed here
    calls = cost = prompt = 0
    for line in (run["out"] / "gateway" / "ledger.jsonl").read_text().splitlines():
        e = json.loads(line)
        if e.get("op") == "settle" and e["key"].startswith(row["episode_id"] + "#"):
            calls += 1
            cost += e["pico"]
            prompt += (e.get("result") or {}).get("prompt_tokens", 0)
    assert (row["llm_calls"], row["prompt_tokens"], row["cost_usd"]) == (calls, prompt, cost / 10**12)


def test_status_and_the_coverage_table_agree_with_the_rows(run):
    out, rows = run["out"], run["rows"]
    counted = _unit_rows(rows)
    expected: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))
    for u in run["plan"]:
        e = expected[u["method"]]
        e["planned"] += 1
        r = counted.get(u["unit_id"])
        state = (
            "not_started"
            if r is None
            else "capped"
            if r["end_reason"] == "budget_exhausted"
            else "gave_up"
            if r["end_reason"] == "infra_error"
            else "finished"
        )
        e[state] += 1
        e["successes"] += int(state == "finished" and r["success"])
    keys = ("planned", "finished", "successes", "capped", "gave_up", "not_started")
    want = {arm: tuple(e[k] for k in keys) for arm, e in expected.items()}
    status = {
        g.method: (g.planned, g.done, g.success, g.budget_stopped, g.failed, g.not_started) for g in collect(RunStore(out)).groups
    }
    con = open_runs([out])
    report = build_report([out])
    con.close()
    table = next(t for s in report.sections for t in s.tables if t.name == "coverage")
    coverage = {r["arm"]: tuple(r[k] for k in keys) for r in table.rows}
    assert status == want
    assert coverage == want
    assert {r["model_label"] for r in table.rows} == {TD} and {r["planned_from"] for r in table.rows} == {"plan.json"}
    assert sum(v[3] for v in want.values()) >= 1 and sum(v[4] for v in want.values()) == 1
    assert sum(v[5] for v in want.values()) >= 1


def test_success_tables_count_finished_units_only(run):
    fin = _finished(run["rows"])
    con = open_runs([run["out"]])
    by_split: dict[tuple[str, str], list[int]] = defaultdict(lambda: [0, 0])
    by_task: dict[tuple[str, str, str], list[int]] = defaultdict(lambda: [0, 0])
    cost: dict[tuple[str, str], float] = defaultdict(float)
    for r in fin:
        split = f"{r['benchmark']}/{r['split']}"
        for d, k in ((by_split, (r["label"], split)), (by_task, (split, r["task"], r["label"]))):
            d[k][0] += 1
            d[k][1] += int(r["success"])
        cost[(r["label"], split)] += r["cost_usd"]
    got = {(r["arm"], r["env_split"]): [r["episodes"], r["successes"]] for r in named_query(con, "success_by_split").dicts()}
    assert got == dict(by_split)
    assert {k[1] for k in got} <= {"robotouille/synchronous", "robotouille/asynchronous", "alfworld/valid_unseen"}
    assert {r["model_label"] for r in named_query(con, "success_by_split").dicts()} == {TD}
    got = {
        (r["env_split"], r["task"], r["arm"]): [r["episodes"], r["successes"]]
        for r in named_query(con, "success_by_task").dicts()
    }
    assert got == dict(by_task)
    got = {(r["arm"], r["env_split"]): r["cost_usd"] for r in named_query(con, "costs").dicts()}
    assert got == pytest.approx(dict(cost), rel=1e-12)
    modes = named_query(con, "failure_modes").dicts()
    assert sum(r["episodes"] for r in modes) == len(fin)
    con.close()


def test_the_ablation_is_paired_with_the_original(run):
    fin = _finished(run["rows"])
    con = open_runs([run["out"]])
    rows = named_query(con, "success_by_ablation").dicts()
    con.close()
    by_key = {(r["instance_id"], r["sampling_seed"]): r for r in fin if r["label"] == "recap"}
    for split in {f"{r['benchmark']}/{r['split']}" for r in fin if r["label"] == "recap-no-think"}:
        variant = [r for r in fin if r["label"] == "recap-no-think" and f"{r['benchmark']}/{r['split']}" == split]
        pairs = [
            (by_key[(r["instance_id"], r["sampling_seed"])], r)
            for r in variant
            if (r["instance_id"], r["sampling_seed"]) in by_key
        ]
        row = next(r for r in rows if r["ablation"] == "no_think" and r["env_split"] == split)
        assert (row["method"], row["episodes"], row["successes"]) == ("recap", len(variant), sum(r["success"] for r in variant))
        assert row["pairs"] == (len(pairs) or None)
        if pairs:
            assert row["original_only"] == sum(o["success"] and not v["success"] for o, v in pairs)
            assert row["variant_only"] == sum(v["success"] and not o["success"] for o, v in pairs)
            assert row["p_value"] is not None


def test_every_section_is_built_from_the_run(run):
    report = build_report([run["out"]])
    names = {s.key for s in report.sections}
    assert {"overview", "success", "costs", "context", "trees", "failures"} <= names
    tables = {t.name for s in report.sections for t in s.tables}
    assert {"coverage", "main", "costs", "trees", "failure_modes"} <= tables
    main = next(t for s in report.sections for t in s.tables if t.name == "main")
    # ALFWorld is one column of the main table; its task types are the rows of its per-task table
    fin = _finished(run["rows"])
    alf_fin = [r for r in fin if r["benchmark"] == "alfworld"]
    assert [c.key for c in main.columns if c.key.startswith("alfworld/")] == (["alfworld/valid_unseen"] if alf_fin else [])
    alf = [t for s in report.sections for t in s.tables if t.name == "tasks_alfworld_valid_unseen"]
    assert [sorted(r["task"] for r in t.rows) for t in alf] == ([sorted({r["task"] for r in alf_fin})] if alf_fin else [])
