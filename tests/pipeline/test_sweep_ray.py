"""Sweeps on a real (local) Ray: end to end through the gateway, a worker killed mid-episode,
the run cap, and a driver killed mid-run then resumed. One Ray session for the module."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from pipeline.cli import main
from pipeline.driver import Driver, Hooks, prepare
from pipeline.gateway_backend import make_backend
from pipeline.spec import parse_spec, with_overrides
from pipeline.sqlview import open_tables
from pipeline.store import RunStore
from tests.pipeline.helpers import TinyBackend

REPO = Path(__file__).resolve().parents[2]


def make_spec(out: Path, body: str) -> tuple[str, object]:
    text = f"run: {out.name}\noutput: {out}\n" + body
    return text, parse_spec(text, "sweep.yaml")


def q(con, sql: str):
    return con.execute(sql).fetchall()


E2E = """models:
  - model: offline/expert
methods:
  - method: recap
  - method: react
environments:
  - benchmark: blocksworld
    tasks: ["3"]
workers: 3
"""


def test_sweep_end_to_end_tables_and_queries(ray_address, tmp_path, capsys):
    out = tmp_path / "e2e"
    text, spec = make_spec(out, E2E)
    prepared = prepare(spec, text)
    summary = Driver(prepared, make_backend(spec), progress="off").run()
    assert (summary.total, summary.finished_now, summary.exit_code()) == (6, 6, 0)
    unit_ids = sorted(u.unit_id for u in prepared.plan.units)

    con, bad = open_tables(RunStore(out))
    assert bad == []
    assert q(con, "select count(*), count(distinct unit_id), count(distinct episode_id) from episodes") == [(6, 6, 6)]
    assert sorted(r[0] for r in q(con, "select unit_id from episodes")) == unit_ids
    assert q(con, "select count(*) from episodes where attempt <> 1 or not test_double or model <> 'offline/expert'") == [(0,)]
    # the expert test double follows the environment's plan: every episode reaches the goal
    assert q(con, "select end_reason, count(*) from episodes group by 1") == [("success", 6)]
    # every message, step, call and tree node belongs to a terminal episode row
    for table in ("messages", "steps", "llm_calls", "tree_nodes"):
        assert q(con, f"select count(*) from {table} t left join episodes e using (episode_id) where e.episode_id is null") == [
            (0,)
        ], table
    assert q(con, "select count(distinct episode_id) from messages") == [(6,)]
    assert q(
        con, "select count(distinct t.episode_id) from tree_nodes t join episodes e using (episode_id) where e.method = 'recap'"
    ) == [(3,)]
    assert q(con, "select count(*) from tree_nodes t join episodes e using (episode_id) where e.method = 'react'") == [(0,)]
    # the gateway's llm_calls rows match each episode's call count; steps match its step count
    assert q(
        con,
        """select count(*) from episodes e
                     where e.llm_calls <> (select count(*) from llm_calls c where c.episode_id = e.episode_id)
                        or e.steps <> (select coalesce(max(s.env_step), 0) from steps s where s.episode_id = e.episode_id)""",
    ) == [(0,)]
    assert q(
        con,
        "select count(*), min(git_revision is not null or true), min(spec_yaml = ?) from run".replace(
            "?", "'" + text.replace("'", "''") + "'"
        ),
    ) == [(1, True, True)]
    kinds = [r[0] for r in q(con, "select kind from events order by ts")]
    assert kinds[0] == "run_started" and kinds[-1] == "run_finished" and "workers_started" in kinds

    # status / show / sql on the finished run
    capsys.readouterr()
    assert main(["status", str(out)]) == 0
    status = capsys.readouterr().out
    assert "units 6/6 done, 6 succeeded" in status and "offline/expert (test double)" in status
    recap_ep = q(con, "select episode_id from episodes where method = 'recap' limit 1")[0][0]
    assert main(["show", str(out), recap_ep]) == 0
    shown = capsys.readouterr().out
    root_v0 = q(con, f"select versions[1].subtasks from tree_nodes where episode_id = '{recap_ep}' and parent_id is null")[0][0]
    first_action = q(con, f"select action from steps where episode_id = '{recap_ep}' order by index limit 1")[0][0]
    assert recap_ep in shown and "Build one tower" in shown
    assert "v0 think: " in shown and f"subtasks: [{root_v0[0]}, {root_v0[1]}" in shown
    assert f"action {first_action} ok" in shown
    assert main(["sql", str(out), "select count(*) as n from episodes"]) == 0
    assert "6" in capsys.readouterr().out

    # running the same spec again starts nothing and writes no terminal row
    again = Driver(prepare(spec, text), make_backend(spec), progress="off").run()
    assert (again.completed_before, again.finished_now, again.exit_code()) == (6, 0, 0)
    con, _ = open_tables(RunStore(out))
    assert q(con, "select count(*) from episodes") == [(6,)]
    assert q(con, "select count(*) from run") == [(2,)]

    # a broken part file is reported by status, never fatal
    (out / "episodes" / "part-broken-000001.parquet").write_bytes(b"PAR1 not really")
    assert main(["status", str(out)]) == 0
    assert "unreadable part file" in capsys.readouterr().out


def test_worker_killed_mid_episode_is_replaced_and_unit_completes(ray_address, tmp_path):
    import ray

    out = tmp_path / "kill"
    text, spec = make_spec(
        out,
        """models: [{model: offline/tiny}]
methods: [{method: recap}]
environments: [{benchmark: blocksworld, instances: [blocksworld/3@1, blocksworld/3@2, blocksworld/3@3, blocksworld/4@1]}]
workers: 2
""",
    )
    killed: dict[str, object] = {}
    backend = TinyBackend(latency_s=0.15)

    def kill_later(unit, attempt, actor):
        if killed:
            return
        killed["unit"] = unit.unit_id
        # every model call waits until the kill: the episode cannot finish first on a loaded machine
        ray.get(backend.budget.hold.remote())

        def kill():
            try:
                time.sleep(0.3)  # into the episode (its reset, maybe a call)
                pid = ray.get(actor.pid.remote())
                killed["pid"] = pid
                os.kill(pid, signal.SIGKILL)
            finally:
                ray.get(backend.budget.release.remote())

        threading.Thread(target=kill, daemon=True).start()

    results: list[tuple[str, int]] = []
    hooks = Hooks(on_dispatch=kill_later, on_result=lambda u, a, o: results.append((u.unit_id, a)))
    summary = Driver(prepare(spec, text, check_keys=False), backend, progress="off", hooks=hooks).run()
    assert (summary.finished_now, summary.worker_restarts, summary.exit_code()) == (4, 1, 0)
    assert (killed["unit"], 1) not in results  # the killed attempt never returned
    con, _ = open_tables(RunStore(out))
    assert q(con, "select count(*), count(distinct unit_id) from episodes") == [(4, 4)]
    assert q(con, f"select attempt, success from episodes where unit_id = '{killed['unit']}'") == [(2, True)]
    lost = q(con, "select unit_id, episode_id, detail from events where kind = 'worker_lost'")
    assert [(r[0], r[1]) for r in lost] == [(killed["unit"], f"{killed['unit']}-1")]
    assert json.loads(lost[0][2])["attempt"] == 1
    assert q(con, "select count(*) from events where kind = 'worker_restarted'") == [(1,)]


CAPPED = """models:
  - model: offline/expert
methods:
  - method: react
environments:
  - benchmark: blocksworld
    tasks: ["3", "4"]
workers: 2
run_cap_usd: 0.015
"""


def test_run_cap_stops_new_work_and_resume_with_higher_cap_continues(ray_address, tmp_path):
    out = tmp_path / "capped"
    text, spec = make_spec(out, CAPPED)
    first = Driver(prepare(spec, text), make_backend(spec), progress="off").run()
    assert first.exit_code() == 3
    # every digit of the cap (it read "$0.01" before)
    assert first.stopped == "run cap $0.015 reached"
    con, _ = open_tables(RunStore(out))
    spent = q(con, "select sum(cost_usd) from llm_calls")[0][0]
    assert 0 < spent <= 0.015
    rows = q(con, "select end_reason from episodes")
    assert len(rows) < 6  # not every unit started
    assert ("budget_exhausted",) in rows
    assert q(con, "select count(*) from events where kind = 'run_cap_reached'") == [(1,)]
    ledger = [json.loads(line) for line in (out / "gateway" / "ledger.jsonl").read_text().splitlines()]
    assert sum(e.get("pico", 0) for e in ledger if e.get("op") == "settle") <= 0.015 * 10**12

    resumed = Driver(prepare(with_overrides(spec, run_cap_usd=100.0), text), make_backend(spec), progress="off").run()
    assert resumed.exit_code() == 0
    con, _ = open_tables(RunStore(out))
    assert q(con, "select count(distinct unit_id) from episodes where end_reason <> 'budget_exhausted'") == [(6,)]
    assert q(
        con,
        "select count(*) from (select unit_id from episodes where end_reason <> 'budget_exhausted' group by unit_id having count(*) > 1)",
    ) == [(0,)]
    assert q(con, "select count(*) from (select episode_id from episodes group by episode_id having count(*) > 1)") == [(0,)]
    # every unit cut by the cap ran again under a later attempt
    assert q(
        con,
        """select count(*) from episodes b where b.end_reason = 'budget_exhausted' and not exists
                     (select 1 from episodes d where d.unit_id = b.unit_id and d.attempt > b.attempt and d.end_reason <> 'budget_exhausted')""",
    ) == [(0,)]


SLOW = """models:
  - model: openai/fake-gpt
    api_base: {url}
    api_key_env: RECAP_FAKE_KEY
methods:
  - method: react
environments:
  - benchmark: blocksworld
    tasks: ["3", "4", "5"]
limits: {llm_calls: 8}
workers: 2
"""


@pytest.fixture(scope="module")
def slow_server():
    """The gateway engineer's fake OpenAI server, answering after 300 ms (a slow provider)."""
    from workers.llm.offline.fake_server import FakeServer, FakeServerConfig

    server = FakeServer(FakeServerConfig(latency_s=0.3))
    server.start_in_thread()
    yield server
    server.stop_thread()


def _terminal_rows(out: Path) -> int:
    eps, _ = RunStore(out).read_table("episodes", ["unit_id"])
    return eps.num_rows


def test_driver_killed_mid_run_then_resume_finishes_without_duplicates(ray_address, slow_server, tmp_path, capsys, monkeypatch):
    out = tmp_path / "crash"
    text, spec = make_spec(out, SLOW.replace("{url}", slow_server.base_url))
    spec_file = tmp_path / "sweep.yaml"
    spec_file.write_text(text)
    monkeypatch.setenv("RECAP_FAKE_KEY", "not-a-secret")
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen(
        [sys.executable, "-m", "pipeline.cli", "run", str(spec_file), "--address", ray_address, "--progress", "off"],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 150
        while _terminal_rows(out) < 1:
            assert proc.poll() is None, "the run ended before it could be killed"
            assert time.monotonic() < deadline, "no episode finished in time"
            time.sleep(0.2)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    before = _terminal_rows(out)
    assert 1 <= before < 9
    # the provider is slow only so that the driver dies mid-run; the resume needs no waiting (the
    # server reads its latency per request: ~10 s less of sleeping on up to 64 calls)
    slow_server.config.latency_s = 0.0
    time.sleep(2.0)  # let Ray reap the dead driver's actors (gateway, sink, workers)

    capsys.readouterr()
    assert main(["resume", str(out), "--progress", "off"]) == 0
    con, _ = open_tables(RunStore(out))
    assert q(con, "select count(*), count(distinct unit_id), count(distinct episode_id) from episodes") == [(9, 9, 9)]
    assert q(con, "select count(*) from episodes where end_reason = 'budget_exhausted'") == [(0,)]
    assert q(con, "select count(*) from run") == [(2,)]
    assert q(con, "select kind from events where kind in ('run_started', 'run_resumed') order by ts") == [
        ("run_started",),
        ("run_resumed",),
    ]
    # every terminal row's messages exist; rows of the killed attempts are orphans, never duplicates
    assert q(
        con, """select count(*) from episodes e where not exists (select 1 from messages m where m.episode_id = e.episode_id)"""
    ) == [(0,)]
    assert q(con, "select count(*) from (select episode_id, seq from messages group by 1, 2 having count(*) > 1)") == [(0,)]


def test_object_store_output_through_a_local_mirror(ray_address, tmp_path, capsys, monkeypatch):
    """An output URI (here file://, any pyarrow filesystem works the same way) is written
    through a local mirror and uploaded; status and sql read the URI."""
    monkeypatch.setenv("RECAP_EVAL_CACHE", str(tmp_path / "cache"))
    uri = f"file://{tmp_path}/bucket/runs/remote"
    text = f"""run: remote
output: {uri}
models: [{{model: offline/tiny}}]
methods: [{{method: recap}}]
environments: [{{benchmark: blocksworld, instances: [blocksworld/3@1, blocksworld/3@2]}}]
workers: 2
"""
    spec = parse_spec(text)
    summary = Driver(prepare(spec, text, check_keys=False), TinyBackend(), progress="off").run()
    assert (summary.finished_now, summary.exit_code()) == (2, 0)
    remote = tmp_path / "bucket" / "runs" / "remote"
    assert {p.name for p in remote.iterdir()} >= {
        "run.json",
        "plan.json",
        "spec.yaml",
        "episodes",
        "messages",
        "steps",
        "tree_nodes",
        "llm_calls",
        "events",
        "run",
    }
    assert not any(p.name.startswith(".tmp-") for p in remote.rglob("*"))
    capsys.readouterr()
    assert main(["status", uri]) == 0
    assert "units 2/2 done, 2 succeeded" in capsys.readouterr().out
    assert main(["sql", uri, "select count(*) as n from episodes where success", "--csv"]) == 0
    assert capsys.readouterr().out.splitlines() == ["n", "2"]


PER_INSTANCE = """models:
  - model: offline/expert
    params: {max_tokens: 64}
methods:
  - method: react
environments:
  - benchmark: blocksworld
    tasks: ["4"]
workers: 2
limits:
  usd: 0.008
"""


def test_a_per_instance_cap_ends_each_episode_under_it_and_the_run_goes_on(ray_address, tmp_path):
    """``limits.usd`` is a reservation at the gateway: no episode's calls cost more than the cap
    (the call that would pass it is refused unsent), each such episode ends ``episode_limit``
    (terminal: resume does not run it again) and nothing else is stopped."""
    out = tmp_path / "per-instance"
    text, spec = make_spec(out, PER_INSTANCE)
    summary = Driver(prepare(spec, text), make_backend(spec), progress="off").run()
    assert (summary.exit_code(), summary.stopped) == (0, None)
    con, _ = open_tables(RunStore(out))
    episodes = q(con, "select episode_id, end_reason, error from episodes order by 1")
    assert [e[1] for e in episodes] == ["episode_limit"] * 3
    assert all(e[2].startswith("episode budget: spent $") and e[2].endswith("> the per-instance cap $0.008000") for e in episodes)
    per_episode = q(
        con,
        """select episode_id, sum(cost_usd), count(*) filter (where status = 'ok'),
                  count(*) filter (where status = 'error' and error_kind = 'budget')
           from llm_calls group by 1 order by 1""",
    )
    assert [(p[0], p[3]) for p in per_episode] == [(e[0], 1) for e in episodes]  # one refused call each, the last
    assert all(0 < p[1] <= 0.008 and p[2] >= 1 for p in per_episode)
    # the refused calls reached no provider: every call's ledger entry is an ok call (the other
    # reservations are the gateway's dollar leases, "lease:<rid>", which name no call)
    ledger = [json.loads(line) for line in (out / "gateway" / "ledger.jsonl").read_text().splitlines()]
    calls = [e for e in ledger if e["op"] == "reserve" and not e["key"].startswith("lease:")]
    assert len(calls) == sum(p[2] for p in per_episode)
    assert {e["key"] for e in calls} == {e["key"] for e in ledger if e["op"] == "settle" and e["status"] == "ok"}
    again = Driver(prepare(spec, text), make_backend(spec), progress="off").run()
    assert again.total == 3 and again.all_done  # episode_limit is an end, not a stop: nothing to resume
    assert q(con, "select count(*) from episodes") == [(3,)]
