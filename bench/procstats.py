"""Per-process memory (PSS) and CPU time of a run's processes, by role, for the bench scripts.

Why PSS and not RSS: Ray's processes share most of their pages (the Python interpreter, Ray's
own libraries, the plasma store); RSS counts a shared page in every process and overstates what
one more episode costs, PSS divides each shared page among the processes that map it, so the
PSS figures of all processes add up to what the machine holds.

Why by descendants: every process of a local Ray cluster (GCS, raylet, dashboard, workers) is
started by the driver that called ``ray.init``, directly or through the raylet, so the driver's
process tree is the run. A fake server in a thread of the driver is counted with the driver.

    from bench.procstats import snapshot, cpu_delta, by_role
    before = snapshot()
    ...                                    # the measured work
    after = snapshot()
    cpu = cpu_delta(before, after)         # {role: CPU seconds spent in the window}
    pss = by_role(after, "pss")            # {role: (processes, PSS bytes)}

Linux only (reads ``/proc``); nothing here asserts a figure.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass

_TICK = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100

#: (substring of the command line, role), first match wins: Ray titles an actor's process
#: ``ray::<ClassName>`` (``ray::<ClassName>.<method>`` while it runs a method)
ROLES: tuple[tuple[str, str], ...] = (
    ("ray::_EpisodeWorker", "episode worker"),
    ("ray::EpisodeWorker", "episode worker"),
    ("ray::GatewayActor", "gateway"),
    ("ray::QuotaActor", "quota"),
    ("ray::BudgetActor", "budget"),
    ("ray::_SinkActor", "sink"),
    ("ray::SinkActor", "sink"),
    ("ray::DashboardAgent", "dashboard agent"),
    ("dashboard/dashboard.py", "dashboard"),
    ("ray::RuntimeEnvAgent", "runtime env agent"),
    ("gcs_server", "gcs"),
    ("raylet", "raylet"),  # before the idle agent: the raylet's command line holds the agent's
    ("idle_dashboard_agent.py", "idle dashboard agent"),
    ("lazy_runtime_env_agent.py", "lazy runtime env agent"),  # until its first request: then ray::RuntimeEnvAgent
    ("log_monitor.py", "log monitor"),
    ("autoscaler/_private/monitor.py", "autoscaler monitor"),
    ("pipeline.local_cluster", "cluster watcher"),
    ("ray::IDLE", "idle worker"),
    ("default_worker.py", "starting worker"),
    ("setup_worker.py", "starting worker"),
)


@dataclass(frozen=True)
class ProcSample:
    """One process at one moment: its role, PSS (bytes) and CPU seconds used since it started."""

    pid: int
    role: str
    pss: int
    rss: int
    cpu_s: float


def role_of(cmdline: str, *, driver: bool = False) -> str:
    """The role a process plays in a run, from its command line (``driver`` for the caller)."""
    if driver:
        return "driver"
    for needle, role in ROLES:
        if needle in cmdline:
            return role
    return "other"


def _read(path: str) -> str:
    try:
        with open(path, "rb") as fh:
            return fh.read().decode(errors="replace")
    except OSError:
        return ""


def _children_map() -> dict[int, list[int]]:
    children: dict[int, list[int]] = {}
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        stat = _read(f"/proc/{name}/stat")
        if not stat:
            continue
        # the command name (field 2) may hold spaces and parentheses: fields start after the last ')'
        fields = stat[stat.rfind(")") + 2 :].split()
        children.setdefault(int(fields[1]), []).append(int(name))
    return children


def descendants(root: int) -> list[int]:
    """``root`` and every process below it."""
    children = _children_map()
    out, todo = [], [root]
    while todo:
        pid = todo.pop()
        out.append(pid)
        todo.extend(children.get(pid, ()))
    return out


def sample(pid: int, *, driver: bool = False) -> ProcSample | None:
    """One process's figures, or None when it is gone (or is a kernel thread)."""
    stat = _read(f"/proc/{pid}/stat")
    cmdline = _read(f"/proc/{pid}/cmdline").replace("\0", " ").strip()
    if not stat or not cmdline:
        return None
    fields = stat[stat.rfind(")") + 2 :].split()
    cpu_s = (int(fields[11]) + int(fields[12])) / _TICK  # utime, stime
    pss = rss = 0
    for line in _read(f"/proc/{pid}/smaps_rollup").splitlines():
        if line.startswith("Pss:"):
            pss = int(line.split()[1]) * 1024
        elif line.startswith("Rss:"):
            rss = int(line.split()[1]) * 1024
    return ProcSample(pid, role_of(cmdline, driver=driver), pss, rss, cpu_s)


def snapshot(root: int | None = None) -> dict[int, ProcSample]:
    """Every live process of the run rooted at ``root`` (default: this process, the driver)."""
    root = os.getpid() if root is None else root
    out = {}
    for pid in descendants(root):
        s = sample(pid, driver=pid == root)
        if s is not None:
            out[pid] = s
    return out


def by_role(samples: dict[int, ProcSample], field: str = "pss") -> dict[str, tuple[int, int]]:
    """{role: (processes, summed field)} for ``pss`` or ``rss``."""
    out: dict[str, tuple[int, int]] = {}
    for s in samples.values():
        n, total = out.get(s.role, (0, 0))
        out[s.role] = (n + 1, total + getattr(s, field))
    return out


def cpu_delta(before: dict[int, ProcSample], after: dict[int, ProcSample]) -> dict[str, float]:
    """{role: CPU seconds spent between two snapshots} (a process born in between counts from
    zero; one that died in between is lost, which the caller avoids by keeping workers alive)."""
    out: dict[str, float] = {}
    for pid, s in after.items():
        spent = s.cpu_s - (before[pid].cpu_s if pid in before else 0.0)
        out[s.role] = out.get(s.role, 0.0) + max(spent, 0.0)
    return out


def fixed_roles(roles: Iterable[str]) -> list[str]:
    """The roles whose memory does not grow with the number of episodes in flight."""
    return [r for r in roles if r not in ("episode worker", "idle worker", "starting worker", "driver", "other")]
