"""Every record type maps to an Arrow schema, and rows round-trip through Parquet exactly."""

from __future__ import annotations

import dataclasses

import pyarrow as pa
import pytest

from schemas import SCHEMA_VERSION, TABLES, arrow_schema, record_to_row
from schemas.parts import PartWriter, check_parts, read_table
from schemas.records import ALL_RECORD_TYPES, CallRecord, MessageRecord, NodeRecord, NodeVersion, StepRecord


def test_each_table_has_run_id_then_the_record_fields_and_a_version():
    assert set(TABLES) == {
        "messages",
        "llm_calls",
        "tree_nodes",
        "steps",
        "episodes",
        "events",
        "run",
        "wiki_pages",
        "wiki_requests",
    }
    for rt in ALL_RECORD_TYPES:
        schema = arrow_schema(rt.table)
        assert schema.names == ["run_id"] + [f.name for f in dataclasses.fields(rt)]
        assert schema.metadata[b"recap_eval_schema_version"] == str(SCHEMA_VERSION).encode()
    calls = arrow_schema("llm_calls")
    assert calls.field("window_seqs").type == pa.list_(pa.int64())
    assert calls.field("node_id").nullable and not calls.field("call_index").nullable
    # the provider model string and the model's name in the sweep (schema version 3), side by side
    assert (calls.field("model").type, calls.field("model").nullable) == (pa.string(), False)
    assert (calls.field("model_name").type, calls.field("model_name").nullable) == (pa.string(), True)
    with pytest.raises(KeyError, match="unknown table 'nope'"):
        arrow_schema("nope")


def test_records_round_trip_through_part_files(tmp_path):
    node = NodeRecord(
        "e1",
        3,
        1,
        2,
        0,
        "cut lettuce",
        "composite",
        "done",
        (NodeVersion(0, "why", ("a", "b"), 4, 9), NodeVersion(1, None, (), None, None)),
        None,
    )
    records = [
        MessageRecord("e1", 0, "user", "task", "hello", None, True),
        CallRecord("e1", 0, "e1#0", "task", (0,), "offline/expert", "ok", prompt_tokens=10, cost_usd=0.25),
        node,
        StepRecord("e1", 0, 1, "pick up B", True, "obs", False, False, 2),
    ]
    w = PartWriter(tmp_path)
    paths = w.write_records("run-1", records)
    assert len(paths) == 4 and not list(tmp_path.rglob(".tmp-*"))
    nodes, bad = read_table(tmp_path, "tree_nodes")
    assert bad == []
    assert nodes.to_pylist() == [record_to_row(node, "run-1")]
    assert nodes.to_pylist()[0]["versions"][0] == {
        "version": 0,
        "think": "why",
        "subtasks": ["a", "b"],
        "call_index": 4,
        "message_seq": 9,
    }
    calls, _ = read_table(tmp_path, "llm_calls")
    assert calls.column("window_seqs").to_pylist() == [[0]]


def test_a_corrupt_part_file_is_reported_not_fatal(tmp_path):
    w = PartWriter(tmp_path, writer="w")
    w.write_records("r", [StepRecord("e", i, i, "a", True, "o", False, False) for i in range(3)])
    good = next((tmp_path / "steps").glob("part-*.parquet"))
    broken = tmp_path / "steps" / "part-x-000001.parquet"
    broken.write_bytes(good.read_bytes()[:40])
    ok, bad = check_parts(tmp_path, "steps")
    assert ok == [good] and [b.path for b in bad] == [broken]
    table, bad = read_table(tmp_path, "steps")
    assert table.num_rows == 3 and len(bad) == 1
    empty, _ = read_table(tmp_path, "episodes")
    assert empty.num_rows == 0 and empty.schema == arrow_schema("episodes")
