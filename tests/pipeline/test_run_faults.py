"""Faults around a running sweep, on a real (local) Ray: the sink actor killed mid-run (it comes
back; nothing acknowledged is lost, no finished unit is run or paid again), the sink gone for
good (the driver stops at once, writes what finished, and a resume re-runs only what was never
written), two drivers started together on one folder (one runs, one refuses in one line), and
units that ended in an infrastructure failure (exit 4, then retried by a corrected re-run)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from pipeline.cli import main
from pipeline.driver import EXIT_INFRA, Driver, Hooks, prepare
from pipeline.errors import PipelineError
from pipeline.spec import parse_spec
from pipeline.sqlview import open_tables
from pipeline.store import RunStore
from tests.pipeline.helpers import TinyBackend

REPO = Path(__file__).resolve().parents[2]

SWEEP = """run: {name}
output: {out}
models: [{{model: offline/tiny}}]
methods: [{{method: react}}]
environments: [{{benchmark: blocksworld, instances: [{instances}]}}]
workers: 2
max_attempts: 3
"""
INSTANCES = [f"blocksworld/{3 + i % 2}@{1 + i // 2}" for i in range(8)]


def q(out: Path, sql: str):
    con, _ = open_tables(RunStore(out))
    return con.execute(sql).fetchall()


def _terminal(out: Path) -> int:
    eps, _ = RunStore(out).read_table("episodes", ["unit_id"])
    return eps.num_rows


def _sweep(tmp_path: Path, name: str) -> tuple[Path, str]:
    out = tmp_path / name
    return out, SWEEP.format(name=name, out=out, instances=", ".join(INSTANCES))


class _Recorder:
    """Hooks that record every dispatched and every returned attempt."""

    def __init__(self) -> None:
        self.dispatched: list[tuple[str, int]] = []
        self.returned: list[tuple[str, int]] = []
        self.hooks = Hooks(
            on_dispatch=lambda u, a, actor: self.dispatched.append((u.unit_id, a)),
            on_result=lambda u, a, o: None if o.crash is not None else self.returned.append((u.unit_id, a)),
        )


def _kill_sink_when(driver: Driver, out: Path, after_rows: int, seen: dict) -> threading.Thread:
    """SIGKILL the driver's sink actor once ``after_rows`` terminal rows are on disk."""
    import ray

    def go() -> None:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and (driver.sink is None or _terminal(out) < after_rows):
            time.sleep(0.05)
        try:
            pid = ray.get(driver.sink.pid.remote(), timeout=30)
            seen["rows_before"] = _terminal(out)
            os.kill(pid, signal.SIGKILL)
            seen["pid"] = pid
            seen["new_pid"] = ray.get(driver.sink.pid.remote(), timeout=60)  # waits for the restart
        except Exception as exc:
            seen["error"] = f"{type(exc).__name__}: {exc}"

    t = threading.Thread(target=go, daemon=True)
    t.start()
    return t


def test_sink_killed_mid_run_comes_back_and_loses_or_repays_nothing(ray_address, tmp_path):
    out, text = _sweep(tmp_path, "sinkkill")
    rec = _Recorder()
    backend = TinyBackend(latency_s=0.1)
    driver = Driver(prepare(parse_spec(text), text, check_keys=False), backend, progress="off", hooks=rec.hooks)
    seen: dict = {}
    killer = _kill_sink_when(driver, out, 2, seen)
    summary = driver.run()
    killer.join(60)
    assert "pid" in seen and seen.get("new_pid") not in (None, seen["pid"]), seen
    assert seen["rows_before"] < len(INSTANCES)  # killed mid-run
    assert (summary.exit_code(), summary.worker_restarts, summary.finished_now) == (0, 0, len(INSTANCES))
    # one attempt per unit, every one of them written with its records
    assert sorted(rec.dispatched) == sorted(rec.returned) and all(a == 1 for _, a in rec.dispatched)
    assert q(out, "select count(*), count(distinct unit_id), max(attempt) from episodes") == [(8, 8, 1)]
    assert q(out, "select count(*) from events where kind in ('worker_lost', 'attempt_failed', 'sink_lost')") == [(0,)]
    assert q(
        out,
        """select count(*) from episodes e where e.steps <> (select count(*) from steps s where s.episode_id = e.episode_id)
                     or not exists (select 1 from messages m where m.episode_id = e.episode_id)""",
    ) == [(0,)]
    assert q(out, "select count(*) from (select episode_id, seq from messages group by 1, 2 having count(*) > 1)") == [(0,)]
    assert not (out / ".sink-wal").exists()

    # a resume has nothing to do and pays nothing
    rec2 = _Recorder()
    again = TinyBackend()
    resumed = Driver(prepare(parse_spec(text), text, check_keys=False), again, progress="off", hooks=rec2.hooks).run()
    assert (resumed.exit_code(), resumed.finished_now, rec2.dispatched) == (0, 0, [])


def test_sink_gone_for_good_stops_the_run_and_resume_reruns_only_what_was_never_written(ray_address, tmp_path, monkeypatch):
    import workers.sink

    monkeypatch.setattr(workers.sink, "SINK_MAX_RESTARTS", 0)  # no restart: the driver's own path
    out, text = _sweep(tmp_path, "sinkgone")
    rec = _Recorder()
    driver = Driver(
        prepare(parse_spec(text), text, check_keys=False), TinyBackend(latency_s=0.1), progress="off", hooks=rec.hooks
    )
    seen: dict = {}
    killer = _kill_sink_when(driver, out, 2, seen)
    with pytest.raises(PipelineError) as err:
        driver.run()
    killer.join(60)
    assert "pid" in seen, seen
    msg = str(err.value)
    assert msg.startswith("the sink actor was lost (") and f"continue with: recap resume {out}" in msg and "\n" not in msg
    assert driver.summary.worker_restarts == 0  # the sink's death is not read as worker deaths
    written = {r[0] for r in q(out, "select unit_id from episodes")}
    # every attempt that returned has its terminal row (written by the driver if need be)
    assert {u for u, _ in rec.returned} <= written
    assert q(out, "select count(*), count(distinct episode_id) from episodes")[0][0] == len(written)
    assert q(out, "select count(*) from events where kind = 'sink_lost'") == [(1,)]
    assert q(
        out,
        """select count(*) from episodes e where not exists
                     (select 1 from messages m where m.episode_id = e.episode_id)""",
    ) == [(0,)]

    monkeypatch.setattr(workers.sink, "SINK_MAX_RESTARTS", 20)
    rec2 = _Recorder()
    resumed = Driver(prepare(parse_spec(text), text, check_keys=False), TinyBackend(), progress="off", hooks=rec2.hooks).run()
    assert resumed.exit_code() == 0
    rerun = {u for u, _ in rec2.dispatched}
    assert rerun == {u.unit_id for u in prepare(parse_spec(text), text, check_keys=False).plan.units} - written
    assert q(out, "select count(*), count(distinct unit_id) from episodes") == [(8, 8)]


def test_two_recap_runs_started_together_give_one_run_and_one_refusal(ray_address, tmp_path):
    out, text = _sweep(tmp_path, "twice")
    spec_file = tmp_path / "sweep.yaml"
    # through the CLI the model is a real test double (the preflight refuses unknown offline/ names)
    spec_file.write_text(text.replace("offline/tiny", "offline/expert"))
    env = dict(os.environ, PYTHONPATH=str(REPO))
    cmd = [sys.executable, "-m", "pipeline.cli", "run", str(spec_file), "--address", ray_address, "--progress", "off"]
    procs = [subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    results = [p.communicate(timeout=300) for p in procs]
    codes = sorted(p.returncode for p in procs)
    assert codes == [0, 2], results
    (refused_err,) = [err for p, (_, err) in zip(procs, results) if p.returncode == 2]
    lines = refused_err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("recap: error: ") and "in use by another driver" in lines[0], lines
    assert q(out, "select count(*), count(distinct unit_id) from episodes") == [(8, 8)]
    assert q(out, "select count(*) from run") == [(1,)]
    assert not (out / "driver.lock").exists()


INFRA = """run: infra
output: {out}
models:
  - model: openai/fake-gpt
    api_base: {url}
    api_key_env: RECAP_FAKE_KEY
    retries: 0
    params: {{max_tokens: 32}}
methods: [{{method: react}}]
environments: [{{benchmark: blocksworld, tasks: ["3"]}}]
limits: {{llm_calls: 3}}
workers: 2
"""


def test_infrastructure_failures_exit_4_and_a_corrected_rerun_retries_them(ray_address, tmp_path, capsys, monkeypatch):
    from workers.llm.offline.fake_server import FakeServer, FakeServerConfig

    monkeypatch.setenv("RECAP_FAKE_KEY", "not-a-secret")
    out = tmp_path / "infra"
    spec_file = tmp_path / "sweep.yaml"
    spec_file.write_text(INFRA.format(out=out, url="http://127.0.0.1:9/v1"))  # a typo: nothing listens there
    assert main(["run", str(spec_file), "--progress", "off"]) == EXIT_INFRA
    said = capsys.readouterr().out
    assert (
        f"3 units ended in an infrastructure failure (server_error 3); fix the cause, then retry them with: recap resume {out}"
        in said
    )
    assert q(out, "select count(*), min(end_reason), max(attempt) from episodes") == [(3, "infra_error", 1)]
    assert main(["status", str(out)]) == 0
    assert "units 0/3 done" in capsys.readouterr().out
    assert main(["resume", str(out), "--progress", "off"]) == EXIT_INFRA  # still broken: tried again, still 4
    assert q(out, "select max(attempt) from episodes") == [(2,)]

    server = FakeServer(FakeServerConfig())
    url = server.start_in_thread()
    try:
        spec_file.write_text(INFRA.format(out=out, url=url))  # the corrected sweep, same output
        capsys.readouterr()
        assert main(["run", str(spec_file), "--progress", "off"]) == 0
    finally:
        server.stop_thread()
    rows = q(out, "select unit_id, attempt, end_reason from episodes order by unit_id, attempt")
    assert len({r[0] for r in rows}) == 3 and len(rows) == 9  # earlier rows stay for the record
    assert {(a, r == "infra_error") for _, a, r in rows} == {(1, True), (2, True), (3, False)}
    assert "units 3/3 done" in capsys.readouterr().out
