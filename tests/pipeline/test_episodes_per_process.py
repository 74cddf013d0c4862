"""Several episodes per worker process (``ray.episodes_per_process``, issue 37 item 3) on a real
(local) Ray: a sweep whose four workers share one process writes exactly the rows of the same
sweep with a process per worker, and a process killed with four attempts in flight costs each
of them one retry. One Ray session for the test run (the ``ray_address`` fixture)."""

from __future__ import annotations

import json
import os
import signal
import threading
import time
from pathlib import Path

import pytest

from pipeline.driver import Driver, Hooks, prepare
from pipeline.gateway_backend import make_backend
from pipeline.spec import parse_spec
from pipeline.sqlview import open_tables
from pipeline.store import RunStore
from pipeline.worker_pool import episodes_per_process
from tests.pipeline.helpers import TinyBackend

SWEEP = """models: [{model: offline/expert}]
methods: [{method: recap}, {method: react}]
environments: [{benchmark: blocksworld, tasks: ["3", "4"]}]
workers: 4
"""


def _spec(out: Path, body: str, per_process: int) -> tuple[str, object]:
    text = f"run: {out.name}\noutput: {out}\n{body}ray: {{episodes_per_process: {per_process}}}\n"
    return text, parse_spec(text, "sweep.yaml")


def q(con, sql: str):
    return con.execute(sql).fetchall()


def _rows(out: Path) -> dict[str, list]:
    con, bad = open_tables(RunStore(out))
    assert bad == []
    return {
        "episodes": q(
            con,
            "select unit_id, episode_id, attempt, end_reason, success, steps, llm_calls, prompt_tokens, completion_tokens, cost_usd, model "
            "from episodes order by unit_id",
        ),
        "messages": q(con, "select episode_id, seq, role, kind, pinned, content from messages order by episode_id, seq"),
        "steps": q(con, "select episode_id, index, action, valid, success from steps order by episode_id, index"),
        "calls": q(con, "select episode_id, count(*) from llm_calls group by episode_id order by episode_id"),
        "tree": q(con, "select episode_id, count(*) from tree_nodes group by episode_id order by episode_id"),
    }


@pytest.mark.slow  # two sweeps
def test_four_episodes_in_one_process_write_the_rows_of_four_processes(ray_address, tmp_path):
    rows, processes, totals = {}, {}, {}
    for k in (1, 4):
        out = tmp_path / f"k{k}"
        text, spec = _spec(out, SWEEP, k)
        actors: set[str] = set()
        hooks = Hooks(on_dispatch=lambda u, a, actor, seen=actors: seen.add(actor._actor_id.hex()))
        summary = Driver(prepare(spec, text), make_backend(spec), progress="off", hooks=hooks).run()
        assert (summary.finished_now, summary.worker_restarts, summary.exit_code()) == (summary.total, 0, 0)
        rows[k], processes[k], totals[k] = _rows(out), len(actors), summary.total
    assert processes == {1: 4, 4: 1}  # four workers: four processes, then one
    assert len(rows[1]["episodes"]) == totals[1] == totals[4] > 4
    assert {r[3] for r in rows[1]["episodes"]} == {"success"}
    assert rows[4] == rows[1]


def test_killing_a_process_of_four_episodes_retries_each_once(ray_address, tmp_path):
    import ray

    out = tmp_path / "kill"
    text, spec = _spec(
        out,
        """models: [{model: offline/tiny}]
methods: [{method: react}]
environments: [{benchmark: blocksworld, instances: [blocksworld/3@1, blocksworld/3@2, blocksworld/3@3, blocksworld/4@1,
  blocksworld/4@2, blocksworld/4@3]}]
workers: 4
""",
        4,
    )
    backend = TinyBackend(latency_s=0.05)
    dispatched: list[tuple[str, int]] = []
    killed: dict[str, object] = {}

    def kill_when_four_run(unit, attempt, actor):
        dispatched.append((unit.unit_id, attempt))
        if len(dispatched) == 1:
            # every model call waits until the kill: no episode can finish first on a loaded machine
            ray.get(backend.budget.hold.remote())
        if len(dispatched) != 4:
            return
        killed["units"] = sorted(u for u, _ in dispatched)

        def kill():
            try:
                time.sleep(0.3)
                os.kill(ray.get(actor.pid.remote()), signal.SIGKILL)
            finally:
                ray.get(backend.budget.release.remote())

        threading.Thread(target=kill, daemon=True).start()

    summary = Driver(
        prepare(spec, text, check_keys=False), backend, progress="off", hooks=Hooks(on_dispatch=kill_when_four_run)
    ).run()
    assert (summary.finished_now, summary.worker_restarts, summary.exit_code()) == (6, 4, 0)
    lost = killed["units"]
    assert len(lost) == 4
    con, _ = open_tables(RunStore(out))
    # one row per unit: the four lost ones at their second attempt, the others at their first
    assert q(con, "select unit_id, attempt, end_reason from episodes order by unit_id") == sorted(
        (u, 2 if u in lost else 1, "success") for u in {u for u, _ in dispatched}
    )
    events = q(con, "select unit_id, episode_id, detail from events where kind = 'worker_lost' order by unit_id")
    assert [(r[0], r[1]) for r in events] == [(u, f"{u}-1") for u in lost]
    assert [json.loads(r[2])["attempt"] for r in events] == [1, 1, 1, 1]
    # each lost attempt retried once: the units dispatched twice are exactly the lost ones
    assert sorted(u for u, a in dispatched if a == 2) == lost
    assert sorted(u for u, a in dispatched if a == 1) == sorted({u for u, _ in dispatched})


def test_auto_keeps_one_episode_per_process_until_four_processes_per_cpu():
    assert [episodes_per_process(w, 2, None) for w in (1, 8, 9, 32, 64, 256)] == [1, 1, 2, 4, 8, 32]
    assert episodes_per_process(256, 2, 1) == 1  # asked: as asked
    assert episodes_per_process(3, 0, None) == 1  # a cluster reporting no CPU counts as one
