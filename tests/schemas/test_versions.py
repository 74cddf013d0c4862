"""A run folder written under schema version 1 stays readable: its episode parts are mapped to
version 2 by every reader (storage, status, the report's views), as schemas/versions.py says."""

from __future__ import annotations

import json

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from pipeline.errors import RunFolderError
from pipeline.store import RunStore
from pipeline.summary import collect
from reports.views import open_runs, run_query
from schemas.parts import read_table
from schemas.tables import arrow_schema

ADDED = ("label", "profile", "ablation", "provider_model")
RECAP_CFG = json.dumps({"window": 64, "think": "none", "max_level": None, "name_only": False, "shortcut": True})


def _v1_row(
    eid: str, method: str, bench: str, split: str, task: str, inst: str, end: str, error: str | None = None, cfg: str = "{}"
) -> dict:
    return {
        "run_id": "old",
        "episode_id": f"{eid}-1",
        "unit_id": eid,
        "attempt": 1,
        "benchmark": bench,
        "split": split,
        "task": task,
        "instance_id": inst,
        "seed": 0,
        "method": method,
        "method_config": cfg,
        "model": "gpt-4o",
        "end_reason": end,
        "success": end == "success",
        "steps": 1,
        "llm_calls": 1,
        "prompt_tokens": 1,
        "cached_prompt_tokens": 0,
        "completion_tokens": 1,
        "cost_usd": 0.5,
        "wall_s": 1.0,
        "step_cap": 10,
        "step_multiplier": 4.0,
        "optimal_steps": None,
        "max_depth": 0,
        "error": error,
        "worker_id": "w",
        "started_at": 1.0,
        "ended_at": 2.0,
        "test_double": False,
    }


ROWS = [
    _v1_row(
        "u1", "recap[paper,level_3]", "robotouille", "synchronous", "6_burger", "robotouille/synchronous/6_burger@42", "success"
    ),
    _v1_row(
        "u2", "my-recap", "alfworld", "heat", "pick_heat_then_place_in_recep", "alfworld/heat/game-1", "step_cap", cfg=RECAP_CFG
    ),
    _v1_row(
        "u3",
        "react",
        "robotouille",
        "",
        "",
        "robotouille/asynchronous/2_soup@84",
        "env_error",
        "gave up after 3 failed attempts (infrastructure: worker_lost); last: ActorDiedError: gone",
    ),
    _v1_row("u4", "react", "alfworld", "put", "pick_and_place_simple", "alfworld/put/game-2", "llm_error", "auth: bad key"),
]


@pytest.fixture()
def v1_run(tmp_path):
    """A run folder as recap wrote it under schema version 1 (run.json, plan.json, one part)."""
    (tmp_path / "run.json").write_text(json.dumps({"run_id": "old", "run": "old", "created_at": 1.0, "schema_version": 1}))
    plan = [
        {
            "unit_id": r["unit_id"],
            "key": r["unit_id"],
            "instance_id": r["instance_id"],
            "method": r["method"],
            "model": "gpt-4o",
            "seed": 0,
        }
        for r in ROWS
    ]
    (tmp_path / "plan.json").write_text(json.dumps({"hash_version": 1, "units": plan}))
    current = arrow_schema("episodes")
    v1 = pa.schema([f for f in current if f.name not in ADDED], metadata={b"recap_eval_schema_version": b"1"})
    (tmp_path / "episodes").mkdir()
    pq.write_table(pa.Table.from_pylist(ROWS, schema=v1), tmp_path / "episodes" / "part-old-000001.parquet")
    return tmp_path


EXPECTED = [
    # (label, method, profile, ablation, split, task, end_reason)
    ("recap[paper,level_3]", "recap", "paper", "level_3", "synchronous", "6_burger", "success"),
    ("my-recap", "my-recap", None, "no_think", "valid_unseen", "heat", "step_cap"),
    ("react", "react", None, None, "asynchronous", "2_soup", "infra_error"),
    ("react", "react", None, None, "valid_unseen", "put", "infra_error"),
]


def test_storage_maps_version_1_episodes(v1_run):
    table, bad = read_table(v1_run, "episodes")
    assert bad == [] and table.schema == arrow_schema("episodes")
    got = [
        (r["label"], r["method"], r["profile"], r["ablation"], r["split"], r["task"], r["end_reason"]) for r in table.to_pylist()
    ]
    assert got == EXPECTED
    assert [r["provider_model"] for r in table.to_pylist()] == [None] * 4
    assert [r["error"] for r in table.to_pylist()] == [r["error"] for r in ROWS]  # kept: the kind reads from it


def test_the_views_and_status_read_a_version_1_run(v1_run):
    con = open_runs([v1_run])
    assert run_query(con, "SELECT count(*) FROM bad_parts").rows == [(0,)]
    assert run_query(con, "SELECT arm, ablation, env_split, state FROM terminal ORDER BY unit_id").rows == [
        ("recap[paper,level_3]", "level_3", "robotouille/synchronous", "finished"),
        ("my-recap", "no_think", "alfworld/valid_unseen", "finished"),
        ("react", "original", "robotouille/asynchronous", "gave_up"),
        ("react", "original", "alfworld/valid_unseen", "gave_up"),
    ]
    con.close()
    report = collect(RunStore(v1_run))
    assert (report.total, report.completed, report.failed, report.failed_kinds) == (4, 2, 2, {"worker_lost": 1, "auth": 1})


def test_a_version_1_run_is_read_not_continued(v1_run):
    with pytest.raises(RunFolderError, match=r"written with schema version 1, this recap writes 3: its rows stay readable"):
        RunStore(v1_run).check_can_hold("old")


# -- version 2 -> 3: llm_calls gained model_name --------------------------------------------------
V2_CALLS = [
    # (model, deployment) as version 2 wrote them -> the model's name in the sweep
    ("offline/expert", "expert-a", "expert-a"),  # labelled: deployment = label
    ("offline/expert", "offline/expert", "offline/expert"),  # unlabelled
    ("openai/gpt-4o", "openai/gpt-4o@http://h:1/v1#KEY", "openai/gpt-4o"),  # unlabelled, base URL + key
    ("openai/gpt-4o", "openai/gpt-4o#KEY", "openai/gpt-4o"),
    ("", None, None),  # a failed call the agent recorded
]


@pytest.fixture()
def v2_run(tmp_path):
    """A run folder as recap wrote it under schema version 2, with an llm_calls part."""
    from schemas.records import CallRecord
    from schemas.tables import record_to_row

    (tmp_path / "run.json").write_text(json.dumps({"run_id": "old", "run": "old", "created_at": 1.0, "schema_version": 2}))
    current = arrow_schema("llm_calls")
    v2 = pa.schema([f for f in current if f.name != "model_name"], metadata={b"recap_eval_schema_version": b"2"})
    rows = []
    for i, (model, deployment, _) in enumerate(V2_CALLS):
        row = record_to_row(CallRecord("e-1", i, f"e-1#{i}", "task", (0,), model, "ok", deployment=deployment), "old")
        del row["model_name"]
        rows.append(row)
    (tmp_path / "llm_calls").mkdir()
    pq.write_table(pa.Table.from_pylist(rows, schema=v2), tmp_path / "llm_calls" / "part-old-000001.parquet")
    return tmp_path


def test_version_2_calls_get_the_model_name_from_their_deployment(v2_run):
    table, bad = read_table(v2_run, "llm_calls")
    assert bad == [] and table.schema == arrow_schema("llm_calls")
    assert [(r["model"], r["deployment"], r["model_name"]) for r in table.to_pylist()] == V2_CALLS
    con = open_runs([v2_run])
    assert run_query(con, "SELECT model_name FROM llm_calls ORDER BY call_index").rows == [(n,) for _, _, n in V2_CALLS]
    con.close()


def test_a_version_2_run_is_continued(v2_run):
    ident = RunStore(v2_run).check_can_hold("old")
    assert (ident.run_id, ident.schema_version) == ("old", 2)
