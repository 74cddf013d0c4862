"""The local Ray cluster a driver starts: who owns it, and cleaning up after a driver that died.

Why: ``ray.init()`` starts a local cluster (GCS, raylet, dashboard, agents, workers) that it
shuts down when the driver exits normally. A driver killed with SIGKILL (the OOM killer, a
``kill -9``, a closed laptop lid in a bad moment) cannot: Ray's kernel fate-sharing takes the
GCS and the raylet with it, but the raylet's agents (``ray::DashboardAgent``,
``ray::RuntimeEnvAgent``) and some workers live on, holding memory and ports until somebody
kills them by hand. Nothing tells which of the machine's Ray processes are whose, and other
users' or other runs' clusters must never be touched.

So every local cluster started by :func:`pipeline.raysetup.init_ray` gets a Ray temp folder of
its own, ``$RECAP_RAY_TMP`` or ``/tmp/recap-ray-<uid>``, one sub-folder per cluster
(``<driver pid>-<random>``: short, since Ray's socket paths live under it), holding an *owner
record* (``recap-owner.json``: the driver's pid and process start time, the host, the run
folder). Every process of that cluster names the folder: on its command line (``--session-dir``,
``--temp-dir``, ``--log-dir``) or in its open files (its logs) - processes that rewrite their
title (``ray::DashboardAgent``) keep their log files open. That, and being a Python interpreter
or one of Ray's binaries (never a ``tail -f`` of a log), is how a cluster's processes are found,
and only those.

* :func:`reap_dead` (``recap run`` / ``recap resume`` at start): every cluster whose owner is
  gone (its pid dead, a zombie, or reused by a process started at another time) has its
  processes stopped - SIGTERM, then SIGKILL after :data:`TERM_WAIT_S` - and its record marked
  ended; the command prints one line per cluster that still had processes.
* :func:`release` (the driver's own clean end, after ``ray.shutdown()``): stragglers of its own
  cluster are stopped the same way and the record is marked ended.
* :func:`watch` (started with the cluster): a small watcher process, in a session of its own,
  reads a pipe whose other end only the driver holds; when the driver dies, however it dies,
  the pipe ends and the watcher stops the cluster's processes at once (logging to
  ``recap-watcher.log`` in the folder) - unless the driver had released it. So a killed driver's
  cluster is usually gone within seconds; :func:`reap_dead` is for when the watcher was killed
  too (``kill -9`` of everything, a container's OOM kill).

The Ray session's logs stay in the folder (they are what explains a crash). Linux only (it
reads ``/proc``); elsewhere nothing is reaped.
"""

from __future__ import annotations

import json
import os
import secrets
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: overrides the folder under which each local cluster gets its Ray temp folder
ROOT_ENV = "RECAP_RAY_TMP"
#: the owner record of a cluster folder while its driver may be alive
OWNER_FILE = "recap-owner.json"
#: the same record once the cluster was shut down (by its driver, or reaped)
ENDED_FILE = "recap-ended.json"
#: seconds a process gets to end after SIGTERM before SIGKILL
TERM_WAIT_S = 5.0
_PROC = Path("/proc")
_PROJECT_ROOT = Path(__file__).resolve().parents[1]
#: the write ends of the watchers' pipes: held (never written) until this process ends
_watch_pipes: dict[Path, int] = {}
_WATCHER = "pipeline.local_cluster watch "


def cluster_root() -> Path:
    """The folder holding one sub-folder per local cluster (per user: another user's clusters
    are neither readable nor killable)."""
    return Path(os.environ.get(ROOT_ENV) or f"/tmp/recap-ray-{os.getuid()}")


def _start_ticks(pid: int) -> int | None:
    """The process's start time (clock ticks since boot), or None when it is gone or a zombie."""
    try:
        stat = (_PROC / str(pid) / "stat").read_text()
    except OSError:
        return None
    fields = stat.rsplit(")", 1)[-1].split()
    if not fields or fields[0] in ("Z", "X"):  # a zombie is dead, only not yet waited for
        return None
    try:
        return int(fields[19])
    except (IndexError, ValueError):
        return None


@dataclass(frozen=True)
class Owner:
    """A cluster folder and what its owner record says."""

    folder: Path
    pid: int
    start_ticks: int | None
    host: str
    run: str
    started_at: float

    def alive(self) -> bool:
        """Whether the driver that started the cluster still runs (same pid, same start time)."""
        if self.host != socket.gethostname():
            return True  # another machine's (a shared /tmp): not ours to judge
        if not _PROC.is_dir():  # no /proc: the pid alone
            try:
                os.kill(self.pid, 0)
            except ProcessLookupError:
                return False
            except OSError:
                return True
            return True
        now = _start_ticks(self.pid)
        return now is not None and (self.start_ticks is None or now == self.start_ticks)


def claim(run: str = "") -> Path:
    """A new cluster folder owned by this process (its record written before Ray starts, so a
    kill at any later moment leaves a cluster :func:`reap_dead` can find)."""
    root = cluster_root()
    root.mkdir(parents=True, exist_ok=True, mode=0o700)
    folder = root / f"{os.getpid()}-{secrets.token_hex(3)}"
    folder.mkdir(mode=0o700)
    record = {
        "pid": os.getpid(),
        "start_ticks": _start_ticks(os.getpid()),
        "host": socket.gethostname(),
        "run": run,
        "started_at": time.time(),
    }
    tmp = folder / (OWNER_FILE + ".tmp")
    tmp.write_text(json.dumps(record) + "\n")
    tmp.replace(folder / OWNER_FILE)
    return folder


def _owners() -> Iterator[Owner]:
    try:
        folders = sorted(cluster_root().iterdir())
    except OSError:
        return
    for folder in folders:
        try:
            rec: dict[str, Any] = json.loads((folder / OWNER_FILE).read_text())
            yield Owner(
                folder,
                int(rec["pid"]),
                rec.get("start_ticks"),
                str(rec.get("host", "")),
                str(rec.get("run", "")),
                float(rec.get("started_at", 0.0)),
            )
        except (OSError, ValueError, KeyError, TypeError):
            continue  # no record (ended, or being written), or not ours


def processes(folder: Path) -> list[int]:
    """The pids of the processes of the cluster in ``folder`` (this process excluded): those
    naming the folder on their command line or holding a file open under it."""
    if not _PROC.is_dir():
        return []
    mark = str(folder.resolve())
    prefix = mark + os.sep
    me = os.getpid()
    found = []
    for entry in _PROC.iterdir():
        if not entry.name.isdigit() or int(entry.name) == me:
            continue
        try:
            cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if _WATCHER in cmdline:
            continue  # the cluster's watcher is no part of it
        if (mark in cmdline or _holds_file_under(entry, prefix)) and _is_ray_program(entry):
            found.append(int(entry.name))
    return found


def _is_ray_program(proc: Path) -> bool:
    """A Python interpreter or one of Ray's own binaries (``gcs_server``, ``raylet``): never a
    ``tail -f`` or an editor that has one of the cluster's logs open."""
    try:
        exe = os.readlink(proc / "exe")
    except OSError:
        return False
    return os.path.basename(exe).startswith("python") or f"{os.sep}ray{os.sep}" in exe


def _holds_file_under(proc: Path, prefix: str) -> bool:
    try:
        fds = list((proc / "fd").iterdir())
    except OSError:  # another user's process, or gone
        return False
    for fd in fds:
        try:
            if os.readlink(fd).startswith(prefix):
                return True
        except OSError:
            continue
    return False


def stop(pids: list[int], wait_s: float = TERM_WAIT_S) -> int:
    """SIGTERM ``pids``, SIGKILL those still alive after ``wait_s``; returns how many were
    signalled (the others had already gone)."""
    signalled = []
    for pid in pids:
        try:
            os.kill(pid, signal.SIGTERM)
            signalled.append(pid)
        except OSError:
            pass
    deadline = time.monotonic() + wait_s
    alive = list(signalled)
    while alive and time.monotonic() < deadline:
        time.sleep(0.1)
        alive = [p for p in alive if _start_ticks(p) is not None]
    for pid in alive:
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass
    return len(signalled)


def _mark_ended(folder: Path) -> None:
    try:
        (folder / OWNER_FILE).replace(folder / ENDED_FILE)
    except OSError:
        pass


def release(folder: Path) -> int:
    """This driver's own cluster after ``ray.shutdown()``: stop what is left of it, mark its
    record ended and let its watcher go; returns how many processes had to be stopped."""
    n = stop(processes(folder))
    _mark_ended(folder)
    w = _watch_pipes.pop(folder, None)
    if w is not None:
        os.close(w)  # the watcher finds the record ended and leaves
    return n


def watch(folder: Path) -> int | None:
    """Start the watcher of this process's cluster in ``folder`` (see the module docstring);
    its pid, or None where it cannot run (no ``/proc``)."""
    if not _PROC.is_dir():
        return None
    r, w = os.pipe()  # both ends non-inheritable: Ray's own subprocesses never hold the write end
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(_PROJECT_ROOT), env.get("PYTHONPATH", "")) if p)
    with open(folder / "recap-watcher.log", "ab") as log:
        proc = subprocess.Popen(
            [sys.executable, "-m", "pipeline.local_cluster", "watch", str(folder)],
            stdin=r,
            stdout=log,
            stderr=log,
            env=env,
            cwd=str(_PROJECT_ROOT),
            start_new_session=True,  # a terminal's Ctrl-C or hang-up does not reach it
        )
    os.close(r)
    _watch_pipes[folder] = w
    return proc.pid


def _watch_main(folder: Path) -> int:
    """The watcher: wait for the driver's end of the pipe to close, then stop the cluster unless
    the driver released it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    while sys.stdin.buffer.read(4096):
        pass
    if not (folder / OWNER_FILE).exists():
        return 0  # released (or already reaped)
    try:
        owner = json.loads((folder / OWNER_FILE).read_text()).get("pid")
    except (OSError, ValueError):
        owner = "?"
    n = stop(processes(folder))
    _mark_ended(folder)
    if n == 0:
        return 0  # a plain ray.shutdown() had ended it (the record is only marked)
    print(
        f"{time.strftime('%Y-%m-%dT%H:%M:%S')} driver pid {owner} ended without shutting its Ray cluster down; "
        f"stopped {n} processes",
        flush=True,
    )
    return 0


@dataclass(frozen=True)
class Reaped:
    """A dead driver's cluster that :func:`reap_dead` stopped."""

    owner: Owner
    stopped: int

    def describe(self) -> str:
        """One line for the user."""
        run = f" (run {self.owner.run})" if self.owner.run else ""
        return (
            f"stopped {self.stopped} processes of the local Ray cluster left by driver pid {self.owner.pid}{run}, "
            f"which ended without shutting it down; its Ray logs are in {self.owner.folder}"
        )


def reap_dead() -> list[Reaped]:
    """Stop the processes of every local cluster whose driver is gone, and mark those records
    ended; returns the clusters that still had processes."""
    out = []
    for owner in _owners():
        if owner.alive():
            continue
        pids = processes(owner.folder)
        n = stop(pids) if pids else 0
        _mark_ended(owner.folder)
        if n:
            out.append(Reaped(owner, n))
    return out


if __name__ == "__main__":  # the watcher (see :func:`watch`)
    if len(sys.argv) == 3 and sys.argv[1] == "watch":
        sys.exit(_watch_main(Path(sys.argv[2])))
    sys.exit(f"usage: {sys.executable} -m pipeline.local_cluster watch FOLDER")
