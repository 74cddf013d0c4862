"""A local cluster started with the dashboard off runs pipeline/idle_dashboard_agent.py, not Ray's agent.

Ray's raylet starts a dashboard agent and shares its fate; with the dashboard and metrics off a
sweep needs only the three port files the raylet waits for (published unused) and a process that
lives as long as the raylet (issue 37, item 3: Ray's agent was ~78 MB PSS of the fixed memory).
Checked on the session's cluster (started by ``init_ray``, dashboard off): which processes its
raylet started and what they published; and the stand-in alone: it writes its files and leaves
when its parent does.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pipeline import idle_dashboard_agent

AGENT = Path(idle_dashboard_agent.__file__)


def _children(pid: int) -> list[list[str]]:
    """The command lines of ``pid``'s child processes."""
    found = []
    for entry in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{entry}/stat") as fh:
                ppid = int(fh.read().rsplit(")", 1)[1].split()[1])
            if ppid != pid:
                continue
            with open(f"/proc/{entry}/cmdline", "rb") as fh:
                found.append(fh.read().decode(errors="replace").split("\0"))
        except (OSError, IndexError, ValueError):
            continue
    return found


@pytest.mark.usefixtures("ray_address")
def test_the_raylet_runs_the_idle_agent_and_sees_its_ports_unused():
    import ray

    from pipeline import raysetup

    if raysetup._owned is None:
        pytest.skip("Ray was started outside init_ray in this process")
    node = ray._private.worker._global_node
    assert node is not None
    session_dir = node.get_session_dir_path()
    raylet = node.all_processes[ray._private.ray_constants.PROCESS_TYPE_RAYLET][0].process.pid
    started = [" ".join(argv) for argv in _children(raylet)]
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


def test_the_idle_agent_publishes_its_ports_and_leaves_with_its_parent(tmp_path):
    files = [tmp_path / "metrics_agent_port_n1", tmp_path / "dashboard_agent_listen_port_n1"]
    args = " ".join(f"--port-file={f}" for f in files)
    # the parent: a shell that starts the agent, reports its pid, waits for a line on stdin, exits
    parent = subprocess.Popen(
        ["sh", "-c", f"{sys.executable} -I -S {AGENT} {args} & echo $!; read line"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert parent.stdout is not None and parent.stdin is not None
    agent = int(parent.stdout.readline())
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
