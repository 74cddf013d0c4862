"""A local cluster started with the dashboard off runs lean agents (issue 37, item 3).

Ray's raylet starts a dashboard agent and a runtime-env agent and shares their fate. With the
dashboard and metrics off a sweep needs only the three port files the raylet waits for (published
unused by pipeline/idle_dashboard_agent.py, in place of Ray's ~78 MB agent), and Ray's runtime-env
agent (~48 MB) only once a worker starts with a runtime_env (pipeline/lazy_runtime_env_agent.py
holds its port and becomes it then). Checked on the session's cluster (started by ``init_ray``,
dashboard off): the raylet's agent commands, what its agents published, a runtime_env task; and
each stand-in alone: its files, leaving with its parent, becoming the agent on a connection.
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pipeline import idle_dashboard_agent, lazy_runtime_env_agent
from tests.pipeline.ray_procs import children, session_cluster

AGENT = Path(idle_dashboard_agent.__file__)
LAZY = Path(lazy_runtime_env_agent.__file__)


@pytest.mark.usefixtures("ray_address")
def test_the_raylet_runs_the_idle_agent_and_sees_its_ports_unused():
    import ray

    session_dir, raylet = session_cluster()
    started = [" ".join(argv) for argv in children(raylet)]
    assert [c for c in started if str(AGENT) in c] and all(
        f"--session-dir={session_dir}" in c for c in started if str(AGENT) in c
    )
    # Ray's own agent is not started (it retitles itself ray::DashboardAgent); the runtime-env agent still is
    assert not [c for c in started if "dashboard/agent.py" in c or "ray::DashboardAgent" in c]
    assert [c for c in started if "runtime_env/agent/main.py" in c or "ray::RuntimeEnvAgent" in c]
    ports = {p.name.rsplit("_", 1)[0]: p.read_text() for p in Path(session_dir).glob("*_port_*")}
    assert {k: ports.get(k) for k in ("metrics_agent_port", "metrics_export_port", "dashboard_agent_listen_port")} == {
        "metrics_agent_port": "-1",
        "metrics_export_port": "-1",
        "dashboard_agent_listen_port": "-1",
    }
    # the node the raylet registered with those ports is alive and runs tasks
    assert ray.get(ray.remote(num_cpus=0)(lambda: 7).remote(), timeout=120) == 7


@pytest.mark.usefixtures("ray_address")
def test_the_raylet_starts_the_runtime_env_agent_through_the_lazy_one_and_it_answers():
    import ray

    session_dir, raylet = session_cluster()
    with open(f"/proc/{raylet}/cmdline", "rb") as fh:
        argv = fh.read().decode().split("\0")
    (command,) = [a for a in argv if a.startswith("--runtime_env_agent_command=")]
    assert f" -I -S {LAZY} --port-file=" in command and "-- " in command
    assert "runtime_env/agent/main.py" in command.split(" -- ", 1)[1]  # Ray's own agent, after the --
    (port_file,) = Path(session_dir).glob("runtime_env_agent_port_*")
    port = port_file.read_text()

    @ray.remote(num_cpus=0, runtime_env={"env_vars": {"RECAP_LAZY_AGENT_PROBE": "yes"}})
    def probe() -> str | None:
        return os.environ.get("RECAP_LAZY_AGENT_PROBE")

    assert ray.get(probe.remote(), timeout=180) == "yes"
    # Ray's agent answered on the port the raylet read at its start, in the lazy agent's process
    assert port_file.read_text() == port
    assert [c for c in children(raylet) if c[0].startswith("ray::RuntimeEnvAgent")]


def _start_under_a_parent(agent_command: str) -> tuple[subprocess.Popen, int]:
    """A parent shell that starts ``agent_command`` in the background, reports its pid and waits
    for a line on stdin before it exits: (the parent, the agent's pid)."""
    parent = subprocess.Popen(
        ["sh", "-c", f"{agent_command} & echo $!; read line"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert parent.stdout is not None and parent.stdin is not None
    return parent, int(parent.stdout.readline())


def test_the_idle_agent_publishes_its_ports_and_leaves_with_its_parent(tmp_path):
    files = [tmp_path / "metrics_agent_port_n1", tmp_path / "dashboard_agent_listen_port_n1"]
    args = " ".join(f"--port-file={f}" for f in files)
    parent, agent = _start_under_a_parent(f"{sys.executable} -I -S {AGENT} {args}")
    deadline = time.monotonic() + 60
    while not all(f.exists() for f in files) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert [f.read_text() for f in files] == ["-1", "-1"]
    assert os.path.exists(f"/proc/{agent}")  # alive while its parent is
    parent.stdin.write("go\n")
    parent.stdin.close()
    parent.wait(timeout=60)
    while _alive(agent) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _alive(agent)


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie is not: it waits only for its reaper)."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def test_the_idle_agent_refuses_to_start_without_a_port_file():
    done = subprocess.run([sys.executable, "-I", "-S", str(AGENT)], capture_output=True, text=True, timeout=60)
    assert (done.returncode, done.stderr.strip()) == (2, "idle_dashboard_agent: no --port-file given")


def test_the_lazy_agent_holds_the_port_and_becomes_the_agent_on_a_connection(tmp_path):
    port_file, seen = tmp_path / "runtime_env_agent_port_n1", tmp_path / "agent.json"
    # a stand-in for Ray's agent: records its pid and command line
    fake = f"import json, os, sys; open({str(seen)!r}, 'w').write(json.dumps([os.getpid(), sys.argv[1:]]))"
    command = [sys.executable, "-c", fake, "--node-ip-address=127.0.0.1", "--runtime-env-agent-port=0", "--x=1"]
    agent = subprocess.Popen([sys.executable, "-I", "-S", str(LAZY), f"--port-file={port_file}", "--", *command])
    try:
        deadline = time.monotonic() + 60
        while not port_file.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        port = int(port_file.read_text())
        assert port > 0
        time.sleep(1.5)  # a poll or more: nothing asked, nothing started
        assert not seen.exists() and agent.poll() is None
        # a caller: its connection is cut off unanswered (the raylet retries it on the agent)
        with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), timeout=30) as caller:
            caller.recv(1)
        assert agent.wait(timeout=60) == 0
    finally:
        agent.kill()
    assert json.loads(seen.read_text()) == [
        agent.pid,
        ["--node-ip-address=127.0.0.1", f"--runtime-env-agent-port={port}", "--x=1"],
    ]


def test_the_lazy_agent_leaves_with_its_parent_without_starting_the_agent(tmp_path):
    port_file, seen = tmp_path / "runtime_env_agent_port_n1", tmp_path / "started"
    command = f"{sys.executable} -c 'open({str(seen)!r}, \"w\")' --runtime-env-agent-port=0"
    parent, agent = _start_under_a_parent(f"{sys.executable} -I -S {LAZY} --port-file={port_file} -- {command}")
    deadline = time.monotonic() + 60
    while not port_file.exists() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert int(port_file.read_text()) > 0 and _alive(agent)
    parent.stdin.write("go\n")
    parent.stdin.close()
    parent.wait(timeout=60)
    while _alive(agent) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _alive(agent) and not seen.exists()


def test_the_lazy_agent_refuses_a_command_line_without_the_agent():
    done = subprocess.run(
        [sys.executable, "-I", "-S", str(LAZY), "--port-file=/nowhere"], capture_output=True, text=True, timeout=60
    )
    assert (done.returncode, done.stderr.strip()) == (2, "lazy_runtime_env_agent: no Ray agent command after --")
