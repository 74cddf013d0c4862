"""A run folder written under an earlier schema version stays readable: its parts are mapped to
the current version by every reader (storage, status, the report's views, ``recap sql`` and
``recap report``), as schemas/versions.py says; a version 2 or 3 folder is continued."""

from __future__ import annotations

import csv
import json

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from pipeline.cli import main as cli_main
from pipeline.errors import RunFolderError
from pipeline.resume import load_state
from pipeline.spec import parse_spec
from pipeline.store import RunStore
from pipeline.summary import collect
from pipeline.units import HASH_VERSION, diff_plans, expand
from reports.views import open_runs, run_query
from schemas.parts import PartWriter, read_table
from schemas.records import EpisodeRecord
from schemas.tables import arrow_schema, record_to_row

ADDED = ("label", "profile", "ablation", "provider_model")


def stored_schema(table: str, version: int, drop: tuple[str, ...] = ()) -> pa.Schema:
    """The table's schema as a part of ``version`` stored it: without ``drop``, episodes'
    ``sampling_seed`` under its old name ``seed`` (before version 4)."""
    fields = [f for f in arrow_schema(table) if f.name not in drop]
    if table == "episodes" and version < 4:
        fields = [f.with_name("seed") if f.name == "sampling_seed" else f for f in fields]
    return pa.schema(fields, metadata={b"recap_eval_schema_version": str(version).encode()})


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
    v1 = stored_schema("episodes", 1, ADDED)
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
    with pytest.raises(RunFolderError, match=r"written with schema version 1, this recap writes 5: its rows stay readable"):
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


# -- version 3 -> 4: episodes.seed renamed sampling_seed ----------------------------------------------
V3_SPEC = """run: old3
output: {out}
models: [{{model: offline/expert}}]
methods: [{{method: react}}]
environments: [{{benchmark: blocksworld, tasks: ["3"]}}]
seeds: [0, 1]
"""


def _episode(unit, success: bool) -> EpisodeRecord:
    return EpisodeRecord(
        episode_id=f"{unit.unit_id}-1",
        unit_id=unit.unit_id,
        attempt=1,
        benchmark="blocksworld",
        split="3",
        task="3",
        instance_id=unit.instance_id,
        sampling_seed=unit.sampling_seed,
        method="react",
        method_config=unit.method_config,
        model="offline/expert",
        end_reason="success" if success else "step_cap",
        success=success,
        steps=4,
        llm_calls=4,
        prompt_tokens=10,
        cached_prompt_tokens=0,
        completion_tokens=2,
        cost_usd=0.0,
        wall_s=1.0,
        step_cap=16,
        step_multiplier=4.0,
        ended_at=float(unit.sampling_seed),
        label="react",
        provider_model="offline/expert",
    )


@pytest.fixture()
def v3_run(tmp_path):
    """A run folder as recap wrote it under schema version 3: spec.yaml with the old ``seeds``
    key, plan.json naming each unit's ``seed``, and the sampling seed 0 units finished in a part
    whose sampling seed column is ``seed``."""
    out = tmp_path / "old3"
    out.mkdir()
    text = V3_SPEC.format(out=out)
    (out / "spec.yaml").write_text(text)
    (out / "run.json").write_text(json.dumps({"run_id": "old3", "run": "old3", "created_at": 1.0, "schema_version": 3}))
    units = expand(parse_spec(text, "spec.yaml")).units
    plan = [{("seed" if k == "sampling_seed" else k): v for k, v in u.summary().items()} for u in units]
    (out / "plan.json").write_text(json.dumps({"hash_version": HASH_VERSION, "units": plan}))
    rows = []
    for u in units:
        if u.sampling_seed == 0:
            row = record_to_row(_episode(u, success=u.instance_id != "blocksworld/3@3"), "old3")
            rows.append({("seed" if k == "sampling_seed" else k): v for k, v in row.items()})
    (out / "episodes").mkdir()
    pq.write_table(pa.Table.from_pylist(rows, schema=stored_schema("episodes", 3)), out / "episodes" / "part-old3-000001.parquet")
    return out


V3_ROWS = [("blocksworld/3@1", 0, True), ("blocksworld/3@2", 0, True), ("blocksworld/3@3", 0, False)]


def test_version_3_episodes_read_with_their_seed_as_sampling_seed(v3_run):
    table, bad = read_table(v3_run, "episodes")
    assert bad == [] and table.schema == arrow_schema("episodes")
    assert sorted((r["instance_id"], r["sampling_seed"], r["success"]) for r in table.to_pylist()) == V3_ROWS
    con = open_runs([v3_run])
    assert run_query(con, "SELECT count(*) FROM bad_parts").rows == [(0,)]
    names = run_query(con, "SELECT * FROM episodes LIMIT 0").columns
    assert "sampling_seed" in names and "seed" not in names
    assert run_query(con, "SELECT instance_id, sampling_seed, success FROM outcomes ORDER BY 1").rows == V3_ROWS
    con.close()


def test_recap_sql_and_report_present_a_version_3_seed_as_sampling_seed(v3_run, tmp_path, capsys):
    rc = cli_main(["sql", str(v3_run), "--csv", "SELECT instance_id, sampling_seed, success FROM outcomes ORDER BY 1"])
    out = capsys.readouterr().out
    assert rc == 0
    assert out.splitlines() == [
        "instance_id,sampling_seed,success",
        "blocksworld/3@1,0,True",
        "blocksworld/3@2,0,True",
        "blocksworld/3@3,0,False",
    ]
    rc = cli_main(["report", str(v3_run), "--format", "csv,html", "--out", str(tmp_path / "rep")])
    capsys.readouterr()
    assert rc == 0
    with open(tmp_path / "rep" / "csv" / "viewer_episodes.csv", newline="") as f:
        episodes = list(csv.DictReader(f))
    assert sorted((e["instance_id"], e["sampling_seed"]) for e in episodes) == [(i, str(s)) for i, s, _ in V3_ROWS]
    assert "seed" not in episodes[0]


def test_a_version_3_run_is_continued_and_its_parts_read_as_one_table(v3_run):
    ident = RunStore(v3_run).check_can_hold("old3")
    assert (ident.run_id, ident.schema_version) == ("old3", 3)
    # the folder's own spec.yaml (old key) gives the plan it stored: every unit unchanged
    spec = parse_spec((v3_run / "spec.yaml").read_text(), "spec.yaml")
    plan = expand(spec)
    diff = diff_plans(json.loads((v3_run / "plan.json").read_text()), plan)
    assert (len(diff.unchanged), diff.new, diff.changed, diff.removed) == (6, [], [], [])
    # the continuation writes the sampling seed 1 units as current-version parts beside the old one
    w = PartWriter(v3_run, "new")
    w.write_records("old3", [_episode(u, success=True) for u in plan.units if u.sampling_seed == 1])
    table, bad = read_table(v3_run, "episodes")
    assert bad == []
    got = sorted((r["instance_id"], r["sampling_seed"]) for r in table.to_pylist())
    assert got == sorted((f"blocksworld/3@{n}", s) for n in (1, 2, 3) for s in (0, 1))
    assert load_state(RunStore(v3_run)).completed == {u.unit_id for u in plan.units}
    con = open_runs([v3_run])
    assert run_query(con, "SELECT sampling_seed, count(*) FROM outcomes GROUP BY 1 ORDER BY 1").rows == [(0, 3), (1, 3)]
    con.close()
