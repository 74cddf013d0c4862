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

The Ray session's logs stay in the folder (they are what explains a crash). Linux only (it
reads ``/proc``); elsewhere nothing is reaped.
"""

from __future__ import annotations

import json
import os
import secrets
import signal
import socket
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
    """This driver's own cluster after ``ray.shutdown()``: stop what is left of it and mark its
    record ended; returns how many processes had to be stopped."""
    n = stop(processes(folder))
    _mark_ended(folder)
    return n


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
