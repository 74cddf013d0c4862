"""Two Ray nodes on loopback (a head and a worker node started with ``ray start``): a sweep
joined with ``--address`` spreads its episode workers over both nodes and completes."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

from pipeline.sqlview import open_tables
from pipeline.store import RunStore

REPO = Path(__file__).resolve().parents[2]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _pids_using(marker: str) -> list[int]:
    """PIDs of processes whose command line names our cluster's private temp dir."""
    out = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            if marker.encode() in (d / "cmdline").read_bytes():
                out.append(int(d.name))
        except OSError:
            continue
    return out


@pytest.mark.slow
def test_sweep_on_two_loopback_nodes(tmp_path):
    ray_bin = str(Path(sys.executable).with_name("ray"))
    temp = f"/tmp/rt-{uuid.uuid4().hex[:8]}"
    port = _free_port()
    # token auth off: a loopback test cluster, and the worker node must not need the head's token
    env = dict(
        os.environ,
        PYTHONPATH=str(REPO),
        RAY_USAGE_STATS_ENABLED="0",
        LITELLM_LOCAL_MODEL_COST_MAP="True",
        RAY_AUTH_MODE="disabled",
    )
    common = ["--num-cpus", "1", "--disable-usage-stats"]
    try:
        subprocess.run(
            [
                ray_bin,
                "start",
                "--head",
                "--port",
                str(port),
                "--node-ip-address",
                "127.0.0.1",
                "--include-dashboard=false",
                "--temp-dir",
                temp,
                *common,
            ],
            env=env,
            check=True,
            capture_output=True,
            timeout=180,
        )
        subprocess.run(
            [ray_bin, "start", "--address", f"127.0.0.1:{port}", "--node-ip-address", "127.0.0.1", *common],
            env=env,
            check=True,
            capture_output=True,
            timeout=180,
        )
        out = tmp_path / "two"
        spec = tmp_path / "sweep.yaml"
        spec.write_text(f"""run: two-nodes
output: {out}
models: [{{model: offline/expert}}]
methods: [{{method: recap}}, {{method: react}}]
environments: [{{benchmark: blocksworld, tasks: ["3"]}}]
workers: 4
""")
        r = subprocess.run(
            [sys.executable, "-m", "pipeline.cli", "run", str(spec), "--address", f"127.0.0.1:{port}", "--progress", "off"],
            env=env,
            capture_output=True,
            text=True,
            timeout=400,
        )
        assert r.returncode == 0, r.stderr[-2000:]
        con, _ = open_tables(RunStore(out))
        assert con.execute("select count(*), count(distinct unit_id) from episodes").fetchall() == [(6, 6)]
        started = json.loads(con.execute("select detail from events where kind = 'workers_started'").fetchall()[0][0])
        assert started["nodes"] == 2
        assert len(set(started["workers"].values())) == 2
    finally:
        for pid in _pids_using(temp):
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass
        time.sleep(1)
