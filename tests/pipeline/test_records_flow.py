"""The record path without Ray: the worker's forwarder, the sink's batching and write order, the
episode client's hints, and what a run folder says is done (resume state)."""

from __future__ import annotations

import json

import pyarrow.parquet as pq

from pipeline.resume import UnitQueue, load_state, parse_episode_id
from pipeline.spec import parse_spec
from pipeline.store import RunStore
from pipeline.units import expand
from recap.llm import ChatMessage, LLMRequest, LLMResponse
from schemas.parts import PartWriter
from schemas.records import CallRecord, EpisodeRecord, EventRecord, MessageRecord
from schemas.tables import record_to_row
from workers.envs.registry import make_env
from workers.episode_worker import EpisodeClient, RecordForwarder
from workers.sink import Sink


def msg(eid: str, seq: int) -> MessageRecord:
    return MessageRecord(eid, seq, "user", "observation", f"m{seq}")


def call(eid: str, i: int) -> CallRecord:
    return CallRecord(eid, i, f"{eid}#{i}", "task", (0,), "m", "ok")


def test_forwarder_batches_and_skips_calls_when_the_gateway_writes_them():
    sent: list[dict] = []
    waited: list[int] = []
    fwd = RecordForwarder(
        "run1", send=lambda rows: sent.append(rows) or len(sent), wait=waited.append, skip_calls=True, batch_rows=3
    )
    for i in range(4):
        fwd(msg("e-1", i))
        fwd(call("e-1", i))
    assert fwd.close() == 4
    assert [{t: len(r) for t, r in b.items()} for b in sent] == [{"messages": 3}, {"messages": 1}]
    assert sent[0]["messages"][0] == {
        "run_id": "run1",
        "episode_id": "e-1",
        "seq": 0,
        "role": "user",
        "kind": "observation",
        "content": "m0",
        "node_id": None,
        "pinned": False,
        "tool_call_id": None,
        "tool_calls": None,
    }
    assert waited == [1, 2]  # the first batch was awaited before the second went out; close waits for the last
    keep = RecordForwarder("run1", send=lambda rows: sent.append(rows), wait=lambda r: None, skip_calls=False)
    keep(call("e-1", 0))
    keep.close()
    assert list(sent[-1]) == ["llm_calls"]


class _OrderWriter:
    def __init__(self) -> None:
        self.tables: list[str] = []

    def write_rows(self, table, rows):
        self.tables.append(table)
        return table


def test_sink_flushes_by_size_and_writes_episode_rows_last(tmp_path):
    sink = Sink(str(tmp_path), "run1", flush_rows=5, flush_s=3600)
    sink.writer = _OrderWriter()
    ep = EpisodeRecord(
        "e-1",
        "e",
        1,
        "blocksworld",
        "3_blocks",
        "t",
        "blocksworld/3@1",
        0,
        "recap",
        "{}",
        "m",
        "success",
        True,
        3,
        3,
        10,
        0,
        5,
        0.0,
        1.0,
        12,
        4.0,
    )
    sink.add_records([ep])
    sink.add({"messages": [record_to_row(msg("e-1", i), "run1") for i in range(2)]})
    assert sink.writer.tables == []  # 3 rows buffered, below the size threshold
    sink.add_records([EventRecord(1.0, "driver", "x"), EventRecord(2.0, "driver", "y")])
    assert sink.writer.tables == ["events", "messages", "episodes"]
    assert sink.stats()["rows_written"] == 5


def test_sink_writes_readable_parts(tmp_path):
    sink = Sink(str(tmp_path), "run1", writer="sinkA")
    sink.add_records([msg("e-1", i) for i in range(3)], flush=True)
    files = sorted((tmp_path / "messages").glob("part-*.parquet"))
    assert [f.name for f in files] == ["part-sinkA-000001.parquet"]
    assert pq.read_table(files[0]).column("seq").to_pylist() == [0, 1, 2]


def test_episode_client_adds_sampling_seed_and_expert_plan_for_offline_models():
    env = make_env("blocksworld/3@1")
    env.reset()
    seen: list[LLMRequest] = []

    class Inner:
        def complete(self, request):
            seen.append(request)
            return LLMResponse(text="{}", model="offline/expert", test_double=True)

    req = LLMRequest(
        messages=(ChatMessage("user", "hi"),), episode_id="e-1", call_index=0, purpose="task", hints={"style": "recap"}
    )
    client = EpisodeClient(Inner(), env, sampling_seed=5, offline=True)
    client.complete(req)
    assert seen[0].hints == {"style": "recap", "sampling_seed": 5, "expert_plan": env.expert_plan()}
    assert req.hints == {"style": "recap"}  # the agent's request is untouched
    assert client.test_double and client.models == {"offline/expert"}
    EpisodeClient(Inner(), env, sampling_seed=1, offline=False).complete(req)
    assert seen[1].hints == {"style": "recap", "sampling_seed": 1}


def test_resume_state_and_queue(tmp_path):
    spec = parse_spec(f"""run: r
output: {tmp_path}
models: [{{model: offline/expert}}]
methods: [{{method: recap}}]
environments: [{{benchmark: blocksworld, tasks: ["3"]}}]
""")
    units = expand(spec).units  # 3 units
    a, b, c = (u.unit_id for u in units)
    w = PartWriter(tmp_path, "t")

    def ep(uid: str, attempt: int, reason: str) -> EpisodeRecord:
        return EpisodeRecord(
            f"{uid}-{attempt}",
            uid,
            attempt,
            "blocksworld",
            "",
            "",
            "x",
            0,
            "recap",
            "{}",
            "m",
            reason,
            reason == "success",
            0,
            0,
            0,
            0,
            0,
            0.0,
            0.0,
            0,
            4.0,
        )

    w.write_records("r", [ep(a, 1, "success"), ep(b, 1, "budget_exhausted")])
    # unit c: a killed attempt 1 (messages only) and a lost worker on attempt 2
    w.write_records(
        "r", [msg(f"{c}-1", 0), EventRecord(1.0, "driver", "worker_lost", unit_id=c, detail=json.dumps({"attempt": 2}))]
    )
    state = load_state(RunStore(tmp_path))
    assert state.completed == {a}
    assert state.budget_stopped == {b}
    assert state.last_attempt == {a: 1, b: 1, c: 2}
    assert state.failures == {c: 1}
    q = UnitQueue(units, state)
    assert len(q) == 2
    first = q.take()
    assert (first.unit.unit_id, first.attempt) == (b, 2)
    assert q.take(lambda u: False) is None
    second = q.take()
    assert (second.unit.unit_id, second.attempt) == (c, 3)
    assert q.retry(second.unit).attempt == 4
    assert parse_episode_id(f"{c}-12") == (c, 12) and parse_episode_id("nohyphen") is None
