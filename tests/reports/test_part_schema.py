"""One rule for a part file whose schema is not its table's: `recap status`, `recap sql` and
`recap report` all skip it and name it (schemas.parts.schema_problem: every column of the
table's Arrow schema in schemas/, with exactly its type; extra columns are ignored).

The run folder is what a finished run of 6 units leaves (run.json, plan.json, parts written by
the sink's PartWriter); the damage is parts written by hand with the right column names but
other types - text that looks like numbers included, which a cast would accept.
"""

from __future__ import annotations

import json
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from pipeline.cli import main as recap_main
from pipeline.spec import parse_spec
from pipeline.store import RunStore
from pipeline.units import expand
from schemas.parts import PartWriter, check_parts, schema_problem
from schemas.records import CallRecord, EpisodeRecord, MessageRecord, StepRecord
from schemas.tables import arrow_schema, record_to_row

SPEC = """run: typed
output: {out}
models: [{{model: offline/expert}}]
methods: [{{method: react}}]
environments: [{{benchmark: blocksworld, tasks: ["3", "4"]}}]
"""


def _episode(uid: str, steps: int = 1) -> EpisodeRecord:
    return EpisodeRecord(
        f"{uid}-1",
        uid,
        1,
        "blocksworld",
        "3",
        "t",
        "blocksworld/3@1",
        0,
        "react",
        "{}",
        "offline/expert",
        "success",
        True,
        steps,
        1,
        10,
        0,
        2,
        0.25,
        1.0,
        12,
        4.0,
    )


def _finished(out: Path) -> list[str]:
    text = SPEC.format(out=out)
    plan = expand(parse_spec(text))
    store = RunStore(out)
    store.create_identity("typed")
    store.write_text("spec.yaml", text)
    store.write_text("plan.json", plan.to_json())
    ids = [u.unit_id for u in plan.units]
    w = PartWriter(out, "sinkA")
    for uid in ids[:2]:
        eid = f"{uid}-1"
        w.write_records(
            "r1",
            [
                MessageRecord(eid, 0, "user", "task", "go"),
                StepRecord(eid, 0, 1, "a", True, "ok", True, True),
                CallRecord(
                    eid, 0, f"{eid}-c0", "act", (0,), "offline/expert", "ok", prompt_tokens=10, completion_tokens=2, cost_usd=0.25
                ),
                _episode(uid),
            ],
        )
    return ids


def _retyped(table: str, rows: list[dict], changes: dict[str, pa.DataType]) -> pa.Table:
    """``rows`` under the table's column names, with ``changes`` giving other types."""
    schema = arrow_schema(table)
    fields = [pa.field(f.name, changes.get(f.name, f.type)) for f in schema]
    data = {f.name: [r[f.name] for r in rows] for f in schema}
    for name, typ in changes.items():
        if pa.types.is_string(typ):
            data[name] = [None if v is None else str(v) for v in data[name]]
        elif pa.types.is_integer(typ):
            data[name] = [None if v is None else int(v) for v in data[name]]
    return pa.table(data, schema=pa.schema(fields))


@pytest.fixture
def damaged(tmp_path: Path) -> tuple[Path, dict[str, Path], list[str]]:
    out = tmp_path / "run"
    ids = _finished(out)
    bad: dict[str, Path] = {}
    # episodes: two more finished units, `steps` and `sampling_seed` (int64) stored as numeric text
    rows = [record_to_row(_episode(uid, steps=3), "r1") for uid in ids[2:4]]
    bad["episodes"] = out / "episodes" / "part-zztext-000001.parquet"
    pq.write_table(_retyped("episodes", rows, {"steps": pa.string(), "sampling_seed": pa.string()}), bad["episodes"])
    # llm_calls: prompt_tokens as int32 (castable without loss) and cost as text
    row = record_to_row(
        CallRecord(f"{ids[2]}-1", 0, "k", "act", (0,), "offline/expert", "ok", prompt_tokens=5, cost_usd=9.0), "r1"
    )
    bad["llm_calls"] = out / "llm_calls" / "part-zzint32-000001.parquet"
    pq.write_table(_retyped("llm_calls", [row], {"prompt_tokens": pa.int32(), "cost_usd": pa.string()}), bad["llm_calls"])
    # messages: seq as double
    row = record_to_row(MessageRecord(f"{ids[2]}-1", 1, "assistant", "reply", "x"), "r1")
    bad["messages"] = out / "messages" / "part-zzfloat-000001.parquet"
    pq.write_table(_retyped("messages", [row], {"seq": pa.float64()}), bad["messages"])
    # steps: a bool column stored as int8
    row = record_to_row(StepRecord(f"{ids[2]}-1", 1, 2, "b", True, "ok", False, False), "r1")
    bad["steps"] = out / "steps" / "part-zzbool-000001.parquet"
    pq.write_table(_retyped("steps", [row], {"valid": pa.int8()}), bad["steps"])
    return out, bad, ids


def test_schema_problem_rule():
    schema = arrow_schema("episodes")
    assert schema_problem("episodes", schema) is None
    extra = schema.append(pa.field("later_column", pa.string()))
    assert schema_problem("episodes", extra) is None  # extra columns are ignored
    assert (
        schema_problem("episodes", pa.schema([f for f in schema if f.name != "sampling_seed"]))
        == "not a episodes part: missing column(s) sampling_seed"
    )
    retyped = pa.schema([pa.field(f.name, pa.string() if f.name == "steps" else f.type) for f in schema])
    assert schema_problem("episodes", retyped) == "not a episodes part: wrong column type(s): steps is string, expected int64"
    nested = pa.schema(
        [pa.field(f.name, pa.list_(pa.int64()) if f.name == "window_seqs" else f.type) for f in arrow_schema("llm_calls")]
    )
    assert schema_problem("llm_calls", nested) is None
    nested = pa.schema(
        [pa.field(f.name, pa.list_(pa.int32()) if f.name == "window_seqs" else f.type) for f in arrow_schema("llm_calls")]
    )
    assert "window_seqs is list<item: int32>, expected list<item: int64>" in schema_problem("llm_calls", nested)


def test_status_sql_and_report_agree_on_parts_of_the_wrong_types(damaged, tmp_path, capsys):
    out, bad, ids = damaged
    for table, path in bad.items():
        good, broken = check_parts(out, table)
        assert [b.path for b in broken] == [path] and path not in good
        assert broken[0].error.startswith(f"ValueError: not a {table} part: wrong column type(s): ")

    # recap status: the two units of the retyped part are not done, every bad part is named
    assert recap_main(["status", str(out)]) == 0
    status = capsys.readouterr().out
    assert "units 2/6 done, 2 succeeded" in status
    assert "spend $0.5000" in status  # the two good calls; the call with cost as text is not counted
    for path in bad.values():
        assert f"unreadable part file {path}: ValueError: not a " in " ".join(status.split())

    # recap sql: the same rows, one warning line per skipped part, exit 0
    rc = recap_main(
        [
            "sql",
            str(out),
            "SELECT (SELECT count(*) FROM episodes) AS e, (SELECT count(*) FROM llm_calls) AS c, "
            "(SELECT count(*) FROM messages) AS m, (SELECT count(*) FROM steps) AS s, "
            "(SELECT sum(cost_usd) FROM llm_calls) AS usd",
            "--json",
        ]
    )
    got = capsys.readouterr()
    assert rc == 0
    assert json.loads(got.out) == [{"e": 2, "c": 2, "m": 2, "s": 2, "usd": 0.5}]
    warnings = got.err.splitlines()
    assert len(warnings) == len(bad)
    for path in bad.values():
        assert any(
            w.startswith(f"warning: skipped unreadable part file {path} (") and "wrong column type(s)" in w for w in warnings
        ), path
    rc = recap_main(["sql", str(out), "SELECT path FROM bad_parts ORDER BY path", "--csv"])
    assert rc == 0 and capsys.readouterr().out.splitlines()[1:] == sorted(str(p) for p in bad.values())

    # recap report: no crash, the same counts, every bad part in the skipped-parts section
    report = tmp_path / "report"
    rc = recap_main(["report", str(out), "--out", str(report), "--format", "md,html"])
    got = capsys.readouterr()
    assert rc == 0, got.err
    assert len(got.err.splitlines()) == len(bad)
    md = (report / "report.md").read_text()
    html = (report / "report.html").read_text()
    assert f"| unreadable part files skipped | {len(bad)} |" in md
    for path in bad.values():
        assert str(path) in md and str(path) in html


def test_a_part_missing_a_column_is_skipped_by_all_three(tmp_path, capsys):
    out = tmp_path / "run"
    ids = _finished(out)
    rows = [record_to_row(_episode(uid), "r1") for uid in ids[2:4]]
    part = out / "episodes" / "part-zzold-000001.parquet"
    schema = pa.schema([f for f in arrow_schema("episodes") if f.name != "test_double"])
    pq.write_table(pa.Table.from_pylist([{k: v for k, v in r.items() if k != "test_double"} for r in rows], schema=schema), part)
    assert recap_main(["status", str(out)]) == 0
    status = capsys.readouterr().out
    assert "units 2/6 done" in status and str(part) in " ".join(status.split())
    assert recap_main(["sql", str(out), "SELECT count(*) AS n FROM episodes", "--csv"]) == 0
    got = capsys.readouterr()
    assert got.out == "n\n2\n" and str(part) in got.err
    assert recap_main(["report", str(out), "--out", str(tmp_path / "rep"), "--format", "md"]) == 0
    capsys.readouterr()
    assert str(part) in (tmp_path / "rep" / "report.md").read_text()
