"""The sink's write-ahead log without Ray: a batch is on disk (logged) before ``add`` returns,
a sink "killed" before it flushed comes back (same writer name) and writes what it had
acknowledged, a batch re-sent after the restart is not written twice, and a driver recovers
the log of a sink that died with its session."""

from __future__ import annotations

import pyarrow.parquet as pq

from schemas.records import EpisodeRecord, EventRecord, MessageRecord
from schemas.tables import record_to_row
from workers.sink import WAL_DIR, Sink, read_segment, records_by_table, recover_wal


def msg(eid: str, seq: int) -> MessageRecord:
    return MessageRecord(eid, seq, "user", "observation", f"m{seq}")


def ep(eid: str) -> EpisodeRecord:
    return EpisodeRecord(
        eid,
        eid.rsplit("-", 1)[0],
        1,
        "blocksworld",
        "3",
        "t",
        "blocksworld/3@1",
        0,
        "react",
        "{}",
        "m",
        "success",
        True,
        1,
        1,
        10,
        0,
        2,
        0.0,
        1.0,
        12,
        4.0,
    )


def rows_of(out, table: str, column: str) -> list:
    files = sorted((out / table).glob("part-*.parquet"))
    return [v for f in files for v in pq.read_table(f, columns=[column]).column(column).to_pylist()]


def test_acknowledged_rows_survive_a_killed_sink_and_a_resent_batch_is_not_doubled(tmp_path):
    sink = Sink(str(tmp_path), "run1", writer="sinkK", flush_rows=10_000, flush_s=3600)
    batch = {"messages": [record_to_row(msg("u1-1", i), "run1") for i in range(3)]}
    sink.add(batch)
    sink.add_records([ep("u1-1")])
    assert not (tmp_path / "messages").exists()  # buffered, not written...
    (seg,) = (tmp_path / WAL_DIR).iterdir()
    assert [sorted(r) for _, r in read_segment(seg)] == [["messages"], ["episodes"]]  # ...but logged
    del sink  # killed: no flush, no close

    again = Sink(str(tmp_path), "run1", writer="sinkK", flush_rows=10_000, flush_s=3600)
    assert again.recovered_rows == 4
    assert rows_of(tmp_path, "messages", "seq") == [0, 1, 2]
    assert rows_of(tmp_path, "episodes", "episode_id") == ["u1-1"]
    # the worker whose acknowledgement the kill swallowed sends the same batch again
    again.add(batch)
    again.add({"messages": [record_to_row(msg("u2-1", 0), "run1")]})
    again.flush()
    assert sorted(rows_of(tmp_path, "messages", "episode_id")) == ["u1-1"] * 3 + ["u2-1"]
    parts = sorted(p.name for p in (tmp_path / "messages").glob("part-*.parquet"))
    assert parts == ["part-sinkK-000001.parquet", "part-sinkK-000002.parquet"]  # numbering went on
    again.close()
    assert not (tmp_path / WAL_DIR).exists()


def test_a_driver_recovers_the_log_of_a_sink_that_died_with_its_session(tmp_path):
    sink = Sink(str(tmp_path), "run1", writer="sinkD", flush_rows=10_000, flush_s=3600)
    sink.add_records([msg("u1-1", 0), msg("u1-1", 1)])
    sink.flush()  # segment 1 in parts
    terminal = records_by_table([ep("u1-1"), EventRecord(1.0, "driver", "x")], "run1")
    sink.add(terminal)  # segment 2: logged only
    with open(next((tmp_path / WAL_DIR).glob("*.wal")), "ab") as fh:
        fh.write(b"\x10\x00\x00\x00torn")  # a kill mid-append: never acknowledged
    del sink

    found = recover_wal(tmp_path)
    assert found.rows == 2
    assert rows_of(tmp_path, "episodes", "episode_id") == ["u1-1"]
    assert rows_of(tmp_path, "messages", "seq") == [0, 1]
    assert not (tmp_path / WAL_DIR).exists()
    from workers.sink import batch_hash

    assert batch_hash(terminal) in found.hashes  # the driver knows its batch was taken
    assert recover_wal(tmp_path).rows == 0  # nothing left, nothing doubled
    assert rows_of(tmp_path, "episodes", "episode_id") == ["u1-1"]


def test_replaying_a_segment_whose_parts_were_written_does_not_duplicate(tmp_path):
    sink = Sink(str(tmp_path), "run1", writer="sinkR", flush_rows=10_000, flush_s=3600)
    sink.add_records([msg("u1-1", 0), ep("u1-1")])
    seg = next((tmp_path / WAL_DIR).glob("*.wal"))
    saved = seg.read_bytes()
    sink.flush()  # parts written, segment retired ...
    seg.write_bytes(saved)  # ... as if the kill came between the parts and the retirement
    recover_wal(tmp_path)
    assert rows_of(tmp_path, "episodes", "episode_id") == ["u1-1"]
    assert rows_of(tmp_path, "messages", "seq") == [0]


def test_tool_call_rows_and_tool_messages_reach_their_parts_through_the_log(tmp_path):
    """The tool_calls table and the messages' tool columns (schema version 5) go through the sink and
    its write-ahead log like every other row: logged, recovered after a kill, written once."""
    from schemas.parts import read_table
    from schemas.records import ToolCallRecord

    calls = '[{"id": "c1", "name": "bash", "arguments": "{\\"command\\": \\"ls\\"}"}]'
    records = [
        MessageRecord("u1-1", 0, "assistant", "reply", "", tool_calls=calls),
        MessageRecord("u1-1", 1, "tool", "tool_result", "a.txt", tool_call_id="c1"),
        ToolCallRecord("u1-1", 0, 0, "bash", '{"command": "ls"}', True, "c1", 0, exit_code=0, duration_s=0.5, output_bytes=6),
        ToolCallRecord("u1-1", 1, 1, "bash", "{oops", False, "c2", 2, error="arguments are not JSON"),
    ]
    sink = Sink(str(tmp_path), "run1", writer="sinkT", flush_rows=10_000, flush_s=3600)
    sink.add_records(records)
    del sink  # killed before it flushed
    again = Sink(str(tmp_path), "run1", writer="sinkT", flush_rows=10_000, flush_s=3600)
    assert again.recovered_rows == 4
    again.add_records(records)  # the batch whose acknowledgement the kill swallowed, sent again: not doubled
    again.close()
    msgs, bad = read_table(tmp_path, "messages")
    assert bad == [] and [(m["seq"], m["tool_call_id"], m["tool_calls"]) for m in msgs.to_pylist()] == [
        (0, None, calls),
        (1, "c1", None),
    ]
    rows, bad = read_table(tmp_path, "tool_calls")
    assert bad == [] and rows.to_pylist() == [record_to_row(r, "run1") for r in records[2:]]


def test_a_resent_batch_is_known_however_many_flushes_the_new_sink_made_before_it_came(tmp_path):
    """Ray re-sends the calls a kill swallowed in no set order with the new calls of other senders:
    the restarted sink may flush several segments before the old batch arrives again (CI saw a
    ninth episode row for eight units). The batches its previous process logged stay known for the
    whole life of the new one, and a segment retired in the last minutes stays known too."""
    sink = Sink(str(tmp_path), "run1", writer="sinkO", flush_rows=10_000, flush_s=3600)
    swallowed = records_by_table([ep("u1-1")], "run1")
    sink.add(swallowed, flush=True)  # logged, written, retired: then the kill took its reply
    del sink
    again = Sink(str(tmp_path), "run1", writer="sinkO", flush_rows=10_000, flush_s=3600)
    for i in range(2, 7):  # other senders' terminal rows, each flushed at once
        again.add(records_by_table([ep(f"u{i}-1")], "run1"), flush=True)
    again.add(swallowed, flush=True)  # the swallowed call, re-sent last
    late = records_by_table([ep("u2-1")], "run1")  # a batch this process took five segments ago, re-sent
    again.add(late, flush=True)
    again.close()
    assert sorted(rows_of(tmp_path, "episodes", "episode_id")) == [f"u{i}-1" for i in range(1, 7)]


def test_segments_older_than_the_window_are_forgotten_but_the_last_two_are_kept(tmp_path, monkeypatch):
    """The window bounds what a long session keeps: past it, only the last two retired segments'
    log files and batch hashes stay (a soak's sink stays flat)."""
    import workers.sink

    monkeypatch.setattr(workers.sink, "_KEEP_DONE_S", 0.0)
    sink = Sink(str(tmp_path), "run1", writer="sinkW", flush_rows=10_000, flush_s=3600)
    for i in range(1, 6):
        sink.add(records_by_table([ep(f"u{i}-1")], "run1"), flush=True)
    done = sorted(p.name for p in (tmp_path / WAL_DIR).glob("*.done"))
    assert done == [".tmp-sinkW-000004.done", ".tmp-sinkW-000005.done"]
    assert len(sink._known_hashes) == 2
    sink.close()
