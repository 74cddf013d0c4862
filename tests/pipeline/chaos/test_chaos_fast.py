"""The cheap part of the chaos suite, in the default run (no Ray): bad inputs, damaged run
folders, resume numbering after a kill, gateway fault events, secrets kept out of Ray's
runtime env, and the socket reader behind the loopback check."""

from __future__ import annotations

import asyncio
import contextlib
import json
import socket
from collections.abc import Iterator
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from pipeline.cli import main
from pipeline.resume import UnitQueue, load_state
from pipeline.spec import parse_spec
from pipeline.store import RunStore
from pipeline.units import expand
from recap.llm import ChatMessage, LLMError, LLMRequest
from schemas.parts import PartWriter
from schemas.records import EpisodeRecord, MessageRecord, StepRecord
from tests.pipeline.chaos import inputs
from tests.pipeline.chaos.folders import damage
from tests.pipeline.chaos.procnet import Listener, listeners, parse_address
from workers.llm.offline.fake_server import FakeServer, FakeServerConfig


@pytest.fixture(scope="module")
def server() -> Iterator[FakeServer]:
    s = FakeServer(FakeServerConfig())
    s.start_in_thread()
    yield s
    s.stop_thread()


# --------------------------------------------------------------------------------------------
# bad input: one line, non-zero exit, no write, no model call
# --------------------------------------------------------------------------------------------
def test_the_base_sweep_of_the_bad_input_cases_is_valid(tmp_path, server, monkeypatch):
    monkeypatch.setenv("RECAP_CHAOS_KEY", "sk-chaos-not-used")
    code, lines, problems = inputs.run_case(inputs.Case("valid", inputs._flags("--dry-run"), ""), tmp_path, server)
    assert (code, lines) == (0, [])
    assert problems == ["exit status 0", "0 stderr lines"]  # the case machinery flags an accepted input


@pytest.mark.parametrize("case", inputs.CASES, ids=[c.name for c in inputs.CASES])
def test_bad_input(case, tmp_path, server, monkeypatch):
    monkeypatch.setenv("RECAP_CHAOS_KEY", "sk-chaos-not-used")
    monkeypatch.delenv("RECAP_CHAOS_UNSET_KEY", raising=False)
    code, lines, problems = inputs.run_case(case, tmp_path, server)
    assert problems == [], lines
    assert code in (1, 2)
    assert lines[0].startswith(("recap: error: ", "error: ")), lines[0]


def test_argparse_errors_are_one_line(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["status"])
    assert exc.value.code == 2
    assert capsys.readouterr().err == (
        "recap: error: status: the following arguments are required: run_dir (see recap status --help)\n"
    )


# --------------------------------------------------------------------------------------------
# damaged run folders (no Ray: the folder is written by hand)
# --------------------------------------------------------------------------------------------
SPEC = """run: damaged
output: {out}
models: [{{model: offline/expert}}]
methods: [{{method: react}}]
environments: [{{benchmark: blocksworld, tasks: ["3", "4"]}}]
"""


def _finished_folder(out: Path) -> list[str]:
    """A run folder as a finished run of 6 units leaves it, two parts per table."""
    text = SPEC.format(out=out)
    plan = expand(parse_spec(text))
    store = RunStore(out)
    store.create_identity("damaged")
    store.write_text("spec.yaml", text)
    store.write_text("plan.json", plan.to_json())
    ids = [u.unit_id for u in plan.units]
    w = PartWriter(out, "sinkA")
    for half in (ids[:2], ids[2:]):
        recs = []
        for uid in half:
            eid = f"{uid}-1"
            recs += [MessageRecord(eid, 0, "user", "task", "go"), StepRecord(eid, 0, 1, "a", True, "ok", True, True)]
            recs.append(
                EpisodeRecord(
                    eid,
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
            )
        w.write_records("r1", recs)
    (out / "tree_nodes").mkdir()
    return ids


def test_damaged_parts_are_named_by_status_and_resume_queues_only_units_whose_rows_were_lost(tmp_path, capsys):
    out = tmp_path / "run"
    ids = _finished_folder(out)
    hit = damage(out)
    assert hit["lost_units"] == set(ids[2:])  # the bigger episodes part was truncated

    assert main(["status", str(out)]) == 0
    status = capsys.readouterr().out
    for table in ("episodes", "messages", "steps", "events"):
        assert f"unreadable part file {hit[table]}" in status, table
    assert "units 2/6 done, 2 succeeded" in status
    assert str(hit["temp"]) not in status

    state = load_state(RunStore(out))
    assert state.completed == set(ids[:2])
    assert sorted(str(b.path) for b in state.bad_parts) == sorted(
        str(hit[t]) for t in ("episodes", "messages", "steps", "events")
    )
    queue = UnitQueue(expand(parse_spec(SPEC.format(out=out))).units, state)
    pending = [queue.take() for _ in range(len(queue))]
    assert sorted((p.unit.unit_id, p.attempt) for p in pending) == sorted((u, 2) for u in ids[2:])


def test_check_parts_names_truncated_empty_and_foreign_parts(tmp_path):
    out = tmp_path / "run"
    _finished_folder(out)
    hit = damage(out)
    store = RunStore(out)
    assert [(b.path, b.error) for b in store.check_parts("events")] == [
        (hit["events"], "ValueError: not a events part: missing column(s) detail, episode_id, kind, run_id, severity (+3 more)")
    ]
    assert [b.error for b in store.check_parts("steps")] == ["ArrowInvalid: Parquet file size is 0 bytes"]
    assert [b.path for b in store.check_parts("messages")] == [hit["messages"]]
    assert store.check_parts("tree_nodes") == []  # the leftover temp file is not a part


# --------------------------------------------------------------------------------------------
# resume after a kill: attempts the ledger journal knows about are not reused
# --------------------------------------------------------------------------------------------
def test_an_attempt_seen_only_in_the_ledger_journal_is_not_reused(tmp_path):
    out = tmp_path / "run"
    text = SPEC.format(out=out)
    plan = expand(parse_spec(text))
    RunStore(out).create_identity("damaged")
    a, b = plan.units[0].unit_id, plan.units[1].unit_id
    (out / "gateway").mkdir(parents=True)
    lines = [
        {"op": "reserve", "rid": 1, "key": f"{a}-1#0", "model": "m", "pico": 5, "owner": "x", "t": 0},
        {"op": "settle", "rid": 1, "key": f"{a}-1#0", "model": "m", "pico": 3, "status": "ok", "t": 0},
        {"op": "reserve", "rid": 2, "key": f"{b}-3#4", "model": "m", "pico": 5, "owner": "x", "t": 0},
    ]
    (out / "gateway" / "ledger.jsonl").write_text("".join(json.dumps(e) + "\n" for e in lines) + '{"op": "res')
    state = load_state(RunStore(out))
    assert state.last_attempt == {a: 1, b: 3}
    assert state.completed == set() and state.failures == {}
    queue = UnitQueue(plan.units, state)
    first, second = queue.take(), queue.take()
    assert [(first.unit.unit_id, first.attempt), (second.unit.unit_id, second.attempt)] == [(a, 2), (b, 4)]


# --------------------------------------------------------------------------------------------
# gateway: every failed attempt is an events row of its class
# --------------------------------------------------------------------------------------------
def _request(i: int, text: str) -> LLMRequest:
    return LLMRequest(messages=(ChatMessage("user", text),), episode_id="u1-1", call_index=i, purpose="task")


def test_gateway_events_for_retried_and_failed_calls(tmp_path, server):
    from workers.gateway.core import DeploymentGateway
    from workers.llm.providers import DeploymentConfig

    server.reset()
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "run.json").write_text(json.dumps({"run_id": "r1"}))
    cfg = DeploymentConfig(
        model="openai/fake-gpt",
        api_base=server.base_url,
        max_attempts=3,
        backoff_initial_s=0.01,
        backoff_max_s=0.02,
        params={"max_tokens": 16},
    )
    gw = DeploymentGateway(cfg, run_dir=run_dir, run_cap_usd=1.0)

    async def go() -> list:
        out = []
        for i, text in enumerate(["a FAKE:500*2", "b FAKE:ctx", "c FAKE:503"]):
            try:
                out.append(await gw.complete(_request(i, text)))
            except LLMError as exc:
                out.append(exc.kind)
        await gw.aclose()
        return out

    ok, ctx, gave_up = asyncio.run(go())
    assert (ok.retries, ctx, gave_up) == (2, "context_length", "server_error")
    evs = pq.read_table(run_dir / "events").to_pylist()
    got = [
        (
            e["source"],
            e["kind"],
            e["severity"],
            e["episode_id"],
            e["unit_id"],
            json.loads(e["detail"])["call_key"],
            json.loads(e["detail"])["call_attempt"],
            json.loads(e["detail"])["kind"],
            json.loads(e["detail"])["status"],
        )
        for e in sorted(evs, key=lambda e: e["ts"])
    ]
    assert got == [
        ("gateway", "retry", "warning", "u1-1", None, "u1-1#0", 1, "server_error", 500),
        ("gateway", "retry", "warning", "u1-1", None, "u1-1#0", 2, "server_error", 500),
        ("gateway", "call_failed", "error", "u1-1", None, "u1-1#1", 1, "context_length", 400),
        ("gateway", "retry", "warning", "u1-1", None, "u1-1#2", 1, "server_error", 503),
        ("gateway", "retry", "warning", "u1-1", None, "u1-1#2", 2, "server_error", 503),
        ("gateway", "call_failed", "error", "u1-1", None, "u1-1#2", 3, "server_error", 503),
    ]
    assert len(server.log) == 3 + 1 + 3


def test_a_budget_refusal_is_not_a_fault_event(tmp_path, server):
    from workers.gateway.core import DeploymentGateway
    from workers.llm.providers import DeploymentConfig

    run_dir = tmp_path / "run"
    run_dir.mkdir()
    cfg = DeploymentConfig(model="openai/fake-gpt", api_base=server.base_url, params={"max_tokens": 16})
    gw = DeploymentGateway(cfg, run_dir=run_dir, run_id="r1", run_cap_usd=0.0)

    async def go() -> str:
        try:
            await gw.complete(_request(0, "x"))
            return "ok"
        except LLMError as exc:
            return exc.kind
        finally:
            await gw.aclose()

    assert asyncio.run(go()) == "budget"
    assert not (run_dir / "events").exists()


def test_a_restarted_budget_authority_leaves_a_ledger_restored_event(tmp_path):
    from workers.gateway.actors import _ledger_restored_event
    from workers.gateway.ledger import BudgetLedger

    (tmp_path / "run.json").write_text(json.dumps({"run_id": "r1"}))
    first = BudgetLedger(tmp_path, run_cap_usd=1.0)
    assert first.reserve("e-1#0", "m", 7_000_000, "gw:dead")["status"] == "reserved"
    first.close()  # the process "dies" with the reservation open
    clean = BudgetLedger(tmp_path / "other", run_cap_usd=1.0)
    _ledger_restored_event(str(tmp_path / "other"), clean)
    assert not (tmp_path / "other" / "events").exists()  # nothing restored: no row
    again = BudgetLedger(tmp_path, run_cap_usd=1.0)
    _ledger_restored_event(str(tmp_path), again)
    (row,) = pq.read_table(tmp_path / "events").to_pylist()
    assert (row["run_id"], row["source"], row["kind"], row["severity"]) == ("r1", "gateway", "ledger_restored", "warning")
    assert json.loads(row["detail"]) == {"orphans": 1, "spent_usd": 7e-06}


# --------------------------------------------------------------------------------------------
# secrets: keys travel to the gateway actors as an argument, never in Ray's runtime env
# --------------------------------------------------------------------------------------------
def test_api_keys_are_not_in_the_runtime_env_and_their_holder_does_not_print_them(monkeypatch):
    import os

    from pipeline.gateway_backend import GatewayBackend
    from workers.gateway.actors import SecretEnv

    key = "sk-chaos-FASTTEST-0123456789"
    monkeypatch.setenv("RECAP_CHAOS_KEY", key)
    backend = GatewayBackend(
        parse_spec("""run: s
output: /nonexistent/never-written
models:
  - {model: openai/fake-gpt, api_base: "http://127.0.0.1:9/v1", api_key_env: RECAP_CHAOS_KEY}
  - {model: offline/expert}
methods: [{method: react}]
environments: [{benchmark: blocksworld, tasks: ["3"]}]
""")
    )
    assert key not in json.dumps(backend._runtime_env())
    secrets = backend._api_keys()
    assert (secrets.names(), repr(secrets), str(secrets)) == (
        ["RECAP_CHAOS_KEY"],
        "SecretEnv(RECAP_CHAOS_KEY)",
        "SecretEnv(RECAP_CHAOS_KEY)",
    )
    monkeypatch.delenv("RECAP_CHAOS_KEY")
    SecretEnv({"RECAP_CHAOS_KEY": key}).apply()
    assert os.environ["RECAP_CHAOS_KEY"] == key


# --------------------------------------------------------------------------------------------
# the socket reader behind the loopback check, and which addresses count as loopback
# --------------------------------------------------------------------------------------------
def test_proc_net_addresses_are_decoded():
    assert parse_address("0100007F:1F90") == ("127.0.0.1", 8080)
    assert parse_address("00000000:0050") == ("0.0.0.0", 80)
    assert parse_address("00000000000000000000000001000000:0016") == ("::1", 22)
    assert parse_address("0000000000000000FFFF00000100007F:01BB") == ("::ffff:127.0.0.1", 443)
    assert Listener(1, "p", "::ffff:127.0.0.1", 1).loopback and Listener(1, "p", "::1", 1).loopback
    assert not Listener(1, "p", "0.0.0.0", 1).loopback and not Listener(1, "p", "::", 1).loopback
    assert not Listener(1, "p", "192.0.2.7", 1).loopback


def test_listeners_of_this_process_are_found_with_their_address():
    import os

    with contextlib.ExitStack() as stack:
        ports = {}
        for host in ("127.0.0.1", "0.0.0.0"):
            s = stack.enter_context(socket.socket(socket.AF_INET, socket.SOCK_STREAM))
            s.bind((host, 0))
            s.listen()
            ports[host] = s.getsockname()[1]
        found = {(x.host, x.port): x.loopback for x in listeners([os.getpid()])}
    assert found[("127.0.0.1", ports["127.0.0.1"])] is True
    assert found[("0.0.0.0", ports["0.0.0.0"])] is False


@pytest.mark.parametrize(
    "address, loopback",
    [
        ("127.0.0.1:6379", True),
        ("localhost:6379", True),
        ("[::1]:6379", True),
        ("10.0.0.5:6379", False),
        ("ray://10.0.0.5:10001", False),
        ("head.example.org:6379", False),
    ],
)
def test_which_cluster_addresses_are_joined_on_the_loopback(address, loopback):
    from pipeline.raysetup import _is_loopback

    assert _is_loopback(address) is loopback
