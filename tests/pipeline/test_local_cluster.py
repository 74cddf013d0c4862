"""The owner records of local Ray clusters (no Ray): a dead driver's cluster processes - found by
the cluster's folder on their command line or in their open files, Python or Ray programs
only - are stopped; a live driver's, and anything else naming the folder, are left alone."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pipeline.local_cluster import ENDED_FILE, OWNER_FILE, ROOT_ENV, Owner, claim, processes, reap_dead, release

REPO = Path(__file__).resolve().parents[2]
SLEEP = "import time; time.sleep(120)"

pytestmark = pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="reads /proc (Linux)")


def _wait(pred, timeout_s: float = 20.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(0.05)
    return pred()


@pytest.fixture
def root(tmp_path, monkeypatch):
    root = tmp_path / "ray"
    monkeypatch.setenv(ROOT_ENV, str(root))
    return root


@pytest.fixture
def procs():
    started: list[subprocess.Popen] = []
    yield started
    for p in started:
        if p.poll() is None:
            p.kill()
            p.wait()


def _dead_drivers_folder(run: str) -> tuple[int, Path]:
    """A driver that claimed a cluster folder and died: (its pid, the folder)."""
    code = f"from pipeline.local_cluster import claim; print(claim({run!r}))"
    env = dict(os.environ, PYTHONPATH=str(REPO))
    p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, env=env, cwd=REPO)
    out, _ = p.communicate(timeout=60)
    assert p.returncode == 0
    return p.pid, Path(out.strip())


def test_reap_dead_stops_the_dead_drivers_cluster_only_and_says_so(root, procs):
    pid, folder = _dead_drivers_folder("runs/x")
    assert json.loads((folder / OWNER_FILE).read_text())["pid"] == pid
    log = folder / "session_1" / "logs" / "raylet.out"
    log.parent.mkdir(parents=True)
    log.write_text("")
    # the dead driver's cluster: one naming the folder on its command line, one with a log open
    # (a process that rewrote its title); a tail -f of that log is no Ray program: left alone
    procs.append(subprocess.Popen([sys.executable, "-c", SLEEP, f"--session-dir={folder}/session_1"]))
    holder = "import os, time; f = open(os.environ['LOG']); time.sleep(120)"
    procs.append(subprocess.Popen([sys.executable, "-c", holder], env=dict(os.environ, LOG=str(log))))
    procs.append(subprocess.Popen(["tail", "-f", str(log)], stdout=subprocess.DEVNULL))
    # a live driver's cluster (this process's): left alone
    mine = claim("runs/live")
    procs.append(subprocess.Popen([sys.executable, "-c", SLEEP, f"--temp-dir={mine}"]))
    assert _wait(lambda: sorted(processes(folder)) == sorted(p.pid for p in procs[:2]))
    assert processes(mine) == [procs[3].pid]

    reaped = reap_dead()

    assert [r.describe() for r in reaped] == [
        f"stopped 2 processes of the local Ray cluster left by driver pid {pid} (run runs/x), which ended "
        f"without shutting it down; its Ray logs are in {folder}"
    ]
    assert [p.wait(10) for p in procs[:2]] == [-signal.SIGTERM, -signal.SIGTERM]
    assert procs[2].poll() is None and procs[3].poll() is None
    assert not (folder / OWNER_FILE).exists() and (folder / ENDED_FILE).exists()
    assert reap_dead() == []  # ended: not looked at again
    assert release(mine) == 1  # the driver's own end stops its stragglers
    assert procs[3].wait(10) == -signal.SIGTERM
    assert (mine / ENDED_FILE).exists()


def test_a_process_that_ignores_sigterm_is_killed(root, procs, monkeypatch):
    import pipeline.local_cluster as lc

    monkeypatch.setattr(lc, "TERM_WAIT_S", 0.5)
    _, folder = _dead_drivers_folder("")
    stubborn = "import signal, time; signal.signal(signal.SIGTERM, signal.SIG_IGN); print('ready', flush=True); time.sleep(120)"
    p = subprocess.Popen([sys.executable, "-c", stubborn, str(folder)], stdout=subprocess.PIPE, text=True)
    procs.append(p)
    assert p.stdout is not None and p.stdout.readline() == "ready\n"
    (reaped,) = lc.reap_dead()
    assert reaped.stopped == 1 and "(run " not in reaped.describe()
    assert p.wait(10) == -signal.SIGKILL


def _stat_ticks(pid: int) -> int:
    return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[-1].split()[19])


def test_an_owner_is_dead_when_its_pid_is_gone_a_zombie_or_reused(tmp_path):
    me, host = os.getpid(), socket.gethostname()
    assert Owner(tmp_path, me, _stat_ticks(me), host, "", 0.0).alive()
    assert not Owner(tmp_path, me, _stat_ticks(me) + 1, host, "", 0.0).alive()  # pid reused by another process
    zombie = subprocess.Popen([sys.executable, "-c", "pass"])
    assert _wait(lambda: Path(f"/proc/{zombie.pid}/stat").read_text().rsplit(")", 1)[-1].split()[0] == "Z")
    assert not Owner(tmp_path, zombie.pid, None, host, "", 0.0).alive()  # exited, not yet waited for
    zombie.wait()
    assert not Owner(tmp_path, zombie.pid, None, host, "", 0.0).alive()
    assert Owner(tmp_path, 1, None, "another-host", "", 0.0).alive()  # not ours to judge


_DRIVER = """
import subprocess, sys, time
from pipeline.local_cluster import claim, release, watch
folder = claim("runs/w")
watcher = watch(folder)
child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)", f"--temp-dir={folder}"], start_new_session=True)
print(folder, watcher, child.pid, flush=True)
if sys.argv[1] == "release":
    time.sleep(0.5)
    print(release(folder), flush=True)
else:
    time.sleep(120)
"""


def _start_driver(how: str) -> tuple[subprocess.Popen, Path, int, int]:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    p = subprocess.Popen([sys.executable, "-c", _DRIVER, how], stdout=subprocess.PIPE, text=True, env=env, cwd=REPO)
    assert p.stdout is not None
    folder, watcher, child = p.stdout.readline().split()
    return p, Path(folder), int(watcher), int(child)


def _gone(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[-1].split()[0]
    except OSError:
        return True
    return state == "Z"


def test_the_watcher_stops_the_cluster_of_a_driver_killed_with_sigkill(root):
    driver, folder, watcher, child = _start_driver("kill")
    try:
        assert processes(folder) == [child]  # the watcher is no part of the cluster
        driver.kill()
        driver.wait()
        assert _wait(lambda: _gone(child) and _gone(watcher))
        assert (folder / ENDED_FILE).exists() and not (folder / OWNER_FILE).exists()
        log = (folder / "recap-watcher.log").read_text()
        assert log.endswith(f" driver pid {driver.pid} ended without shutting its Ray cluster down; stopped 1 processes\n")
        assert reap_dead() == []
    finally:
        if not _gone(child):
            os.kill(child, signal.SIGKILL)


def test_after_a_clean_release_the_watcher_leaves_without_a_word(root):
    driver, folder, watcher, child = _start_driver("release")
    out, _ = driver.communicate(timeout=60)
    assert (driver.returncode, out) == (0, "1\n")  # the straggler stopped by release
    assert _wait(lambda: _gone(child) and _gone(watcher))
    assert (folder / ENDED_FILE).exists()
    assert (folder / "recap-watcher.log").read_text() == ""
