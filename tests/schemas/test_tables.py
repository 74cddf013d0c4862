"""Every record type maps to an Arrow schema, and rows round-trip through Parquet exactly."""

from __future__ import annotations

import dataclasses

import pyarrow as pa
import pytest

from schemas import SCHEMA_VERSION, TABLES, arrow_schema, record_to_row
from schemas.parts import PartWriter, check_parts, read_table
from schemas.records import ALL_RECORD_TYPES, CallRecord, MessageRecord, NodeRecord, NodeVersion, StepRecord, ToolCallRecord


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
        "tool_calls",
        "evaluations",
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
    # tool calls (schema version 5): the messages' tool columns are nullable text, and the
    # tool_calls table's optional columns are nullable
    msgs = arrow_schema("messages")
    assert [(n, msgs.field(n).type, msgs.field(n).nullable) for n in ("tool_call_id", "tool_calls")] == [
        ("tool_call_id", pa.string(), True),
        ("tool_calls", pa.string(), True),
    ]
    tools = arrow_schema("tool_calls")
    assert [(f.name, str(f.type), f.nullable) for f in tools] == [
        ("run_id", "string", False),
        ("episode_id", "string", False),
        ("index", "int64", False),
        ("step_index", "int64", False),
        ("name", "string", False),
        ("arguments", "string", False),
        ("valid", "bool", False),
        ("call_id", "string", True),
        ("message_seq", "int64", True),
        ("node_id", "int64", True),
        ("error", "string", True),
        ("exit_code", "int64", True),
        ("duration_s", "double", False),
        ("output_bytes", "int64", False),
        ("timed_out", "bool", False),
    ]
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


def test_tool_call_rows_and_tool_messages_round_trip(tmp_path):
    calls = '[{"id": "c1", "name": "bash", "arguments": "{\\"command\\": \\"ls\\"}"}]'
    records = [
        MessageRecord("e1", 0, "assistant", "reply", "", tool_calls=calls),
        MessageRecord("e1", 1, "tool", "tool_result", "a.txt", tool_call_id="c1"),
        ToolCallRecord("e1", 0, 0, "bash", '{"command": "ls"}', True, "c1", 0, None, None, 0, 0.25, 6, False),
        ToolCallRecord("e1", 1, 1, "bash", "{oops", False, "c2", 2, error="arguments are not JSON"),
    ]
    PartWriter(tmp_path).write_records("r", records)
    msgs, bad = read_table(tmp_path, "messages")
    assert bad == []
    assert [(m["role"], m["tool_call_id"], m["tool_calls"]) for m in msgs.to_pylist()] == [
        ("assistant", None, calls),
        ("tool", "c1", None),
    ]
    rows, bad = read_table(tmp_path, "tool_calls")
    assert bad == [] and rows.to_pylist() == [record_to_row(r, "r") for r in records[2:]]
    assert rows.to_pylist()[1]["exit_code"] is None and rows.to_pylist()[1]["duration_s"] == 0.0
