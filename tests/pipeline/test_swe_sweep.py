"""Coding sweeps on a real (local) Ray: ReCAP (tool calls) and ReAct (mini-SWE-agent's bash loop)
with the offline expert resolve the fixture tasks in Docker and in local sandboxes; every tool
call is in Parquet; a worker killed mid-episode leaves no sandbox behind."""

from __future__ import annotations

import http.client
import json
import os
import re
import signal
import subprocess
import threading
import time
from pathlib import Path

import pytest

from pipeline.driver import Driver, Hooks, prepare
from pipeline.errors import PipelineError
from pipeline.gateway_backend import make_backend
from pipeline.spec import parse_spec
from pipeline.sqlview import open_tables
from pipeline.store import RunStore
from reports.webview.server import serve, stop
from workers.envs.swe.examples import make_fixtures
from workers.sandbox import LABEL_EPISODE, LABEL_RUN

SPEC = """run: {name}
output: {out}
models:
  - model: offline/expert
methods:
  - method: recap
    profile: paper
  - method: react
    profile: paper
environments:
  - benchmark: swe
    tasks: [all]
    options: {{instances_file: "{tasks}", sandbox: {kind}}}
workers: 2
"""

NAMES = ("offbyone", "format", "twofiles", "newfunc", "p2p")


def q(con, sql: str):
    return con.execute(sql).fetchall()


def _sweep(tmp_path: Path, kind: str, names: tuple[str, ...] = NAMES):
    fixtures = make_fixtures(tmp_path / "fixtures", names)
    out = tmp_path / f"run-{kind}"
    text = SPEC.format(name=out.name, out=out, tasks=fixtures.tasks_file, kind=kind)
    spec = parse_spec(text, "sweep.yaml")
    return out, spec, text


def _containers(**labels: str) -> list[str]:
    filters = [f"--filter=label={k}={v}" for k, v in labels.items()]
    done = subprocess.run(["docker", "ps", "-aq", *filters], capture_output=True, text=True, check=True)
    return done.stdout.split()


class _FirstContainer:
    """A driver hook: once the first dispatched episode's container runs, ``act(container ids,
    worker actor)`` in a thread (the episode it acted on and the ids it saw are kept).

    The sweep's gateways are paused from that first dispatch until ``act`` has run, so every
    episode waits at its next model call: the first one cannot finish before it is acted on,
    however loaded the machine (its container start alone outlasts the pause's round trip)."""

    def __init__(self, act, backend) -> None:
        self.act = act
        self.backend = backend
        self.episode = ""
        self.seen: list[str] = []

    def hook(self, unit, attempt, actor) -> None:
        import ray

        if self.episode:
            return
        self.episode = f"{unit.unit_id}-{attempt}"
        ray.get([g.pause.remote() for g in self.backend.actors.values()])
        threading.Thread(target=self._wait_then_act, args=(actor,), daemon=True).start()

    def _wait_then_act(self, actor) -> None:
        import ray

        try:
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline and not self.seen:
                self.seen = _containers(**{LABEL_EPISODE: self.episode})
                time.sleep(0.02)
            self.act(self.seen, actor)
        finally:
            ray.get([g.resume.remote() for g in self.backend.actors.values()])


def _check_run(out: Path, n: int) -> None:
    con, bad = open_tables(RunStore(out))
    assert bad == []
    # every unit resolved its task: 5 fixtures x (recap, react)
    assert q(con, "select method, end_reason, count(*) from episodes group by 1, 2 order by 1") == [
        ("react", "success", n),
        ("recap", "success", n),
    ]
    # ReCAP acts through tool calls, each answered by a tool message (the last submit ends the
    # episode before its answer), and its tree has the review-and-submit node above the task
    recap_calls = q(
        con,
        """select count(*), count(distinct t.episode_id || t.call_id), bool_and(t.valid), bool_and(t.message_seq is not null)
           from tool_calls t join episodes e using (episode_id) where e.method = 'recap'""",
    )
    assert recap_calls[0][0] == recap_calls[0][1] and recap_calls[0][2:] == (True, True)
    assert q(
        con,
        """select count(*) from messages m join episodes e using (episode_id)
           where e.method = 'recap' and m.role = 'tool'
             and (m.episode_id, m.tool_call_id) not in (select (episode_id, call_id) from tool_calls)""",
    ) == [(0,)]
    assert q(
        con,
        """select count(*) from episodes e where e.method = 'recap' and
             (select count(*) from tool_calls t where t.episode_id = e.episode_id and t.name = 'submit') <> 2""",
    ) == [(0,)]
    assert q(
        con,
        """select distinct n.task from tree_nodes n join episodes e using (episode_id)
           where e.method = 'recap' and n.parent_id is null""",
    ) == [("review and submit",)]
    # ReAct writes shell commands as text: each is a bash row without a call id, the last the sentinel
    assert q(
        con,
        """select distinct t.name, t.call_id is null from tool_calls t join episodes e using (episode_id)
           where e.method = 'react'""",
    ) == [("bash", True)]
    # every tool call row is one steps row of its episode
    assert q(
        con,
        """select count(*) from tool_calls t left join steps s
             on s.episode_id = t.episode_id and s."index" = t.step_index where s.episode_id is null""",
    ) == [(0,)]


@pytest.mark.docker
def test_a_docker_sweep_resolves_every_fixture_and_leaves_no_container(ray_address, docker_ready, tmp_path):
    out, spec, text = _sweep(tmp_path, "docker")
    prepared = prepare(spec, text)
    summary = Driver(prepared, make_backend(spec), progress="off").run()
    assert (summary.total, summary.finished_now, summary.exit_code()) == (10, 10, 0)
    _check_run(out, len(NAMES))
    run_id = RunStore(out).identity().run_id
    assert _containers(**{LABEL_RUN: run_id}) == []


def test_a_local_sandbox_sweep_resolves_every_fixture(ray_address, tmp_path):
    out, spec, text = _sweep(tmp_path, "local")
    summary = Driver(prepare(spec, text), make_backend(spec), progress="off").run()
    assert (summary.total, summary.finished_now, summary.exit_code()) == (10, 10, 0)
    _check_run(out, len(NAMES))
    # the viewer shows one ReCAP episode's commands: a row per tool call, in order
    con, _ = open_tables(RunStore(out))
    episode = q(con, "select episode_id from episodes where method = 'recap' and instance_id = 'swe/fixture__twofiles-1'")[0][0]
    calls = q(con, f"select name from tool_calls where episode_id = '{episode}' order by index")
    server, thread = serve([out], 0, poll_s=0)
    try:
        conn = http.client.HTTPConnection("127.0.0.1", server.server_address[1], timeout=30)
        conn.request("GET", f"/episode?id={episode}")
        body = conn.getresponse().read().decode()
    finally:
        stop(server, thread)
    section = re.search(r'<section id="tool-calls">(.*?)</section>', body, re.S)
    assert section is not None
    shown = re.findall(r"<tr[^>]*data-tool-call[^>]*>.*?<td[^>]*><code>(\w+)</code></td>", section.group(1), re.S)
    assert shown == [name for (name,) in calls]
    assert shown.count("str_replace") == 2 and shown[-2:] == ["submit", "submit"]  # two files fixed, review, submit


@pytest.mark.docker
def test_a_killed_workers_container_is_removed_and_its_unit_resolves(ray_address, docker_ready, tmp_path):
    import ray

    out, spec, text = _sweep(tmp_path, "docker", ("offbyone", "format"))
    backend = make_backend(spec)
    killed = _FirstContainer(lambda ids, actor: os.kill(ray.get(actor.pid.remote()), signal.SIGKILL), backend)
    summary = Driver(prepare(spec, text), backend, progress="off", hooks=Hooks(on_dispatch=killed.hook)).run()
    con, _ = open_tables(RunStore(out))
    rows = q(con, "select unit_id, attempt, end_reason, error from episodes order by 1, 2")
    assert (summary.finished_now, summary.worker_restarts, summary.exit_code()) == (4, 1, 0), (rows, summary)
    assert len(killed.seen) == 1  # the killed attempt's container was running
    assert _containers(**{LABEL_EPISODE: killed.episode}) == []
    con, _ = open_tables(RunStore(out))
    assert q(con, "select count(*) from episodes where end_reason = 'success'") == [(4,)], q(
        con, "select unit_id, attempt, end_reason, error from episodes order by 1, 2"
    )
    removed = q(con, "select detail->>'removed', detail->>'worker' is not null from events where kind = 'leftovers_removed'")
    assert ("1", True) in removed


@pytest.mark.docker
def test_a_container_removed_under_its_episode_is_infrastructure_and_resume_runs_it_again(ray_address, docker_ready, tmp_path):
    """The container service failing under an episode (here: its container removed while the agent
    works) is not the agent's 0 %: the row is ``infra_error`` with a ``sandbox:`` error, the session
    exits as an infrastructure failure, and the next session runs that unit again."""
    from pipeline.run_summary import EXIT_INFRA

    out, spec, text = _sweep(tmp_path, "docker", ("offbyone", "format"))
    backend = make_backend(spec)
    removed = _FirstContainer(
        lambda ids, actor: subprocess.run(["docker", "rm", "-f", *ids], capture_output=True, check=True), backend
    )
    first = Driver(prepare(spec, text), backend, progress="off", hooks=Hooks(on_dispatch=removed.hook)).run()
    con, _ = open_tables(RunStore(out))
    rows = q(con, "select episode_id, end_reason, error from episodes order by 1")
    assert (first.exit_code(), first.infra_kinds, first.finished_now) == (EXIT_INFRA, {"sandbox": 1}, 3), rows
    failed = [r for r in rows if r[1] != "success"]
    assert [(r[0], r[1]) for r in failed] == [(removed.episode, "infra_error")], rows
    # where the removal met the episode (its start, a command, its evaluation) varies; the kind does not
    assert re.match(
        r"sandbox: (reset failed: )?swe/fixture__(offbyone|format)-1: the sandbox (cannot be opened|failed): ", failed[0][2]
    )
    again = Driver(prepare(spec, text), make_backend(spec), progress="off").run()
    assert (again.finished_now, again.exit_code()) == (1, 0)
    unit = removed.episode.rsplit("-", 1)[0]
    con, _ = open_tables(RunStore(out))
    assert q(con, f"select attempt, end_reason from episodes where unit_id = '{unit}' order by 1") == [
        (1, "infra_error"),
        (2, "success"),
    ]


@pytest.mark.docker
def test_a_resume_removes_the_containers_a_killed_driver_left(ray_address, docker_ready, tmp_path):
    """A driver killed with SIGKILL leaves its episodes' containers; the next session of the run
    removes every container carrying the run's label before its workers start."""
    out, spec, text = _sweep(tmp_path, "docker", ("offbyone",))
    first = Driver(prepare(spec, text), make_backend(spec), progress="off").run()
    assert first.exit_code() == 0
    run_id = RunStore(out).identity().run_id
    # what a SIGKILLed driver's worker leaves: a running container with the run's labels
    left = subprocess.run(
        [
            "docker",
            "run",
            "-d",
            "--network",
            "none",
            f"--label={LABEL_RUN}={run_id}",
            f"--label={LABEL_EPISODE}=gone-1",
            docker_ready,
            "sleep",
            "600",
        ],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    assert _containers(**{LABEL_RUN: run_id}) == [left[:12]]
    again = Driver(prepare(spec, text), make_backend(spec), progress="off").run()
    assert (again.finished_now, again.exit_code()) == (0, 0)
    assert _containers(**{LABEL_RUN: run_id}) == []
    con, _ = open_tables(RunStore(out))
    assert q(con, "select detail->>'removed' from events where kind = 'leftovers_removed'") == [("1",)]


def test_sandboxes_per_node_caps_the_workers_of_a_coding_sweep(ray_address, tmp_path):
    """The test cluster's node declares one sandbox slot: a coding sweep asking for the bound runs
    one episode worker however many it asks for, and resolves its tasks."""
    out, spec, text = _sweep(tmp_path, "local", ("offbyone", "format"))
    text = text + "ray: {sandboxes_per_node: 1}\n"
    spec = parse_spec(text, "sweep.yaml")
    summary = Driver(prepare(spec, text), make_backend(spec), progress="off").run()
    assert (summary.finished_now, summary.exit_code()) == (4, 0)
    con, _ = open_tables(RunStore(out))
    started = q(con, "select detail->>'workers' from events where kind = 'workers_started'")
    assert len(started) == 1 and len(json.loads(started[0][0])) == 1  # workers: 2 asked, 1 slot


def test_sandboxes_per_node_without_the_resource_is_refused(ray_address, tmp_path, monkeypatch):
    import ray

    out, spec, text = _sweep(tmp_path, "local", ("offbyone",))
    text = text + "ray: {sandboxes_per_node: 2}\n"
    spec = parse_spec(text, "sweep.yaml")
    monkeypatch.setattr(ray, "cluster_resources", lambda: {"CPU": 2.0})
    backend = make_backend(spec)
    driver = Driver(prepare(spec, text), backend, progress="off")
    with pytest.raises(PipelineError) as err:
        driver.run()
    # refused before any actor started: no sink, no budget or gateway
    assert (driver.channel.actor, backend.budget, backend.actors) == (None, None, {})
    assert str(err.value) == (
        "ray.sandboxes_per_node is 2 but no node of the cluster declares the resource recap_sandbox "
        """(start its nodes with --resources '{"recap_sandbox": 2}', or leave the setting out)"""
    )


def test_sandboxes_per_node_bounds_worker_actors_so_the_in_process_executor_runs_without_the_resource(
    ray_address, tmp_path, monkeypatch
):
    """The bound is a Ray resource of the episode-worker actors; threads of the driver take none,
    so ``--executor in-process`` is not refused on a cluster that does not declare it."""
    import ray

    out, spec, text = _sweep(tmp_path, "local", ("offbyone",))
    text = text + "ray: {sandboxes_per_node: 2}\n"
    spec = parse_spec(text, "sweep.yaml")
    monkeypatch.setattr(ray, "cluster_resources", lambda: {"CPU": 2.0})
    summary = Driver(prepare(spec, text), make_backend(spec), progress="off", executor="in-process").run()
    assert (summary.finished_now, summary.exit_code()) == (2, 0)
