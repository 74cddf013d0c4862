"""Signals to ``recap run`` through the real CLI: Ctrl-C once or twice, and SIGKILL + resume.

* sigint (``presses=1``): a Ctrl-C (SIGINT to the command's process group, as a terminal sends
  it) while calls are in flight: no unit starts any more, the episodes in flight finish, exit
  130 with a ``recap resume`` hint; every call the provider answered is in the ledger and in
  ``llm_calls``; the resume finishes the rest and pays no call twice.
* sigint (``presses=2``): the second Ctrl-C cuts the episodes in flight: exit 130, every call the
  provider answered is in the ledger (settled, or held at its worst case), every settled call
  has its ``llm_calls`` row; the resume re-runs only the cut attempts.
* orphans: ``recap run`` on a local Ray cluster of its own, SIGKILLed mid-run: the cluster's
  watcher stops what the driver left within seconds; then ``recap resume`` SIGKILLed together
  with its cluster's watcher: the processes left are counted; the next ``recap resume`` stops
  them, says so in one line, finishes; afterwards no process of any of the three clusters is
  left, and the only calls paid again are those of the attempts in flight at the kills.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from tests.pipeline.chaos.harness import (
    Lab,
    ScenarioResult,
    attempt_of,
    blocks,
    calls_by_episode,
    fake_model,
    journal,
    rows,
    sweep,
    terminal,
    unit_of,
    wait_until,
)


def _first_reserve(ledger: Path) -> bool:
    return ledger.exists() and b'"op":"reserve"' in ledger.read_bytes()


def _cli(lab: Lab, args: list[str], env: dict[str, str]) -> subprocess.Popen:
    """The CLI in a session of its own: a signal to its process group is a terminal's Ctrl-C."""
    return lab.cli(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)


class _Reader:
    """The command's output as it comes (a second Ctrl-C waits until the first one was seen:
    two signals that arrive while the interpreter is inside one blocking call count once)."""

    def __init__(self, proc: subprocess.Popen) -> None:
        self.proc = proc
        self.lines: list[str] = []
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(line)

    def saw(self, text: str) -> bool:
        return any(text in line for line in self.lines)

    def wait(self, timeout: float = 600) -> str:
        try:
            self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self._thread.join(30)
        return "".join(self.lines)


def _output(proc: subprocess.Popen, timeout: float = 600) -> str:
    return _Reader(proc).wait(timeout)


def _said(text: str) -> list[str]:
    """The command's own lines (``recap: ...``, the resume hint): the details of a check."""
    return [line for line in text.splitlines() if line.startswith("recap:") or "recap resume" in line]


def _money(out: Path) -> dict[str, Any]:
    """The ledger journal read per call: settled ok, charged (worst case, orphaned), still open."""
    # a gateway's dollar lease ("lease:<rid>") is a reservation that names no call
    entries = [e for e in journal(out) if not str(e.get("key", "")).startswith("lease:")]
    reserved = {e["key"] for e in entries if e.get("op") == "reserve"}
    settled = {e["key"]: e for e in entries if e.get("op") == "settle"}
    return {
        "ok": {k for k, e in settled.items() if e.get("status") == "ok"},
        "charged": {k for k, e in settled.items() if e.get("status") != "ok" and e.get("pico", 0) > 0},
        "open": reserved - set(settled),
        "reserved": reserved,
    }


def _served(server: Any) -> int:
    return sum(1 for c in server.log if c.status == 200 and c.mode == "ok")


def _repaid(out: Path, done_at_stop: dict[str, int], cut: set[str]) -> tuple[int, set[str]]:
    """Calls paid (settled ok or charged) by attempts cut at the stop, and the units completed
    at the stop that were run again (must be none)."""
    money = _money(out)
    paid = money["ok"] | money["charged"]
    repaid_calls = sum(1 for k in paid if k.rsplit("#", 1)[0] in cut)
    rerun = {unit_of(k.rsplit("#", 1)[0]) for k in money["reserved"]}
    rerun = {
        u
        for u in rerun
        if u in done_at_stop
        and any(
            unit_of(k.rsplit("#", 1)[0]) == u and attempt_of(k.rsplit("#", 1)[0]) > done_at_stop[u] for k in money["reserved"]
        )
    }
    return repaid_calls, rerun


def sigint(lab: Lab, presses: int = 1, units: int = 6) -> ScenarioResult:
    """Ctrl-C ``presses`` times during ``recap run``, then ``recap resume``."""
    res = ScenarioResult(f"SIGINT x{presses} + recap resume")
    res.begin_run()
    address = lab.ray_address()
    server = lab.server(latency_s=0.3, prefix_memory=0)
    base = lab.folder(f"sigint-{presses}")
    out = base / "run"
    spec = base / "sweep.yaml"
    spec.write_text(sweep(out, fake_model(server.base_url), blocks(units), workers=2, llm_calls=6))
    common = ["--address", address, "--progress", "lines"]
    proc = _cli(lab, ["run", str(spec), *common], lab.env())
    reader = _Reader(proc)
    started = wait_until(lambda: proc.poll() is not None or _first_reserve(out / "gateway" / "ledger.jsonl"), 300, 0.05)
    res.check("calls were in flight when Ctrl-C came", started and proc.poll() is None, proc.poll())
    os.killpg(proc.pid, signal.SIGINT)
    # episodes under way at Ctrl-C: their calls reserved, no terminal row yet
    at_signal = {k.rsplit("#", 1)[0] for k in _money(out)["reserved"]} - {r["episode_id"] for r in terminal(out).rows}
    if presses > 1:
        seen = wait_until(lambda: proc.poll() is not None or reader.saw("recap: stopping: "), 60, 0.02)
        res.check("the first Ctrl-C was seen before the second", seen and proc.poll() is None, proc.poll())
        os.killpg(proc.pid, signal.SIGINT)
    text = reader.wait()
    res.check("exit status 130", proc.returncode == 130, f"exit {proc.returncode}: {_said(text)}")
    res.check(
        "says it stops and waits for the episodes in flight",
        "recap: stopping: no new units; waiting up to 60s for the 2 episodes in flight to finish (Ctrl-C again to stop now)"
        in text,
        _said(text),
    )
    if presses > 1:
        res.check(
            "the second Ctrl-C cuts them",
            "recap: stopping now: 2 episodes in flight are cut; the calls they made stay recorded and the resume runs them again"
            in text,
            _said(text),
        )
    hint = f"continue with: recap resume {out}"
    res.check("prints the resume hint", hint in text, _said(text))
    term = terminal(out)
    done_at_stop = {u: r["attempt"] for u, r in term.completed.items()}
    finished = {r["episode_id"] for r in term.rows}
    money = _money(out)
    reserved_eps = {k.rsplit("#", 1)[0] for k in money["reserved"]}
    cut = reserved_eps - finished
    calls = calls_by_episode(out)
    short = [r["episode_id"] for r in term.rows if len(calls.get(r["episode_id"], [])) != r["llm_calls"]]
    res.check("every finished episode has all its llm_calls rows", not short, short[:3])
    rows_n = len(rows(out, "llm_calls", ["call_key"]))
    res.check(
        "every settled call has its llm_calls row", rows_n == len(money["ok"]), f"{rows_n} rows, {len(money['ok'])} settled"
    )
    served = _served(server)
    if presses == 1:
        res.check("no episode was cut", not cut, sorted(cut))
        res.check(
            "the ledger's settled calls are exactly the calls the provider answered",
            len(money["ok"]) == served and not money["open"],
            f"{len(money['ok'])} settled, {len(money['open'])} open, {served} served",
        )
    else:
        res.check("the episodes in flight were cut", len(cut) == 2, sorted(cut))
        res.check(
            "every call the provider answered is in the ledger (settled or held at its worst case)",
            served <= len(money["ok"]) + len(money["open"]) + len(money["charged"]),
            f"{len(money['ok'])} settled, {len(money['open'])} open, {len(money['charged'])} charged, {served} served",
        )
    in_flight_calls = sum(1 for k in money["reserved"] if k.rsplit("#", 1)[0] in cut)
    resume = _cli(lab, ["resume", str(out), *common], lab.env())
    text2 = _output(resume)
    res.check("the resume exits 0", resume.returncode == 0, f"exit {resume.returncode}: {text2.strip().splitlines()[-3:]}")
    term = terminal(out)
    res.check("lost 0, duplicated 0", not term.lost and term.duplicated == 0, (len(term.lost), term.duplicated))
    res.lost += len(term.lost)
    res.duplicated += term.duplicated
    repaid_calls, rerun = _repaid(out, done_at_stop, cut)
    res.check("no unit finished before the stop was run again", not rerun, sorted(rerun))
    if presses == 1:
        res.check("no call paid twice", repaid_calls == 0, repaid_calls)
    res.add_overspend(0.0)
    res.notes.append(
        f"exit 130; {len(at_signal)} episodes in flight at the first Ctrl-C, {len(cut)} of them cut; "
        f"{len(done_at_stop)}/{units} units done at the stop; calls re-paid {repaid_calls} (calls of the cut episodes: {in_flight_calls})"
    )
    res.end_run()
    return res


def _watcher_of(folder: Path) -> list[int]:
    mark = f"pipeline.local_cluster watch {folder}".encode()
    out = []
    for entry in Path("/proc").iterdir():
        try:
            if entry.name.isdigit() and mark in (entry / "cmdline").read_bytes().replace(b"\0", b" "):
                out.append(int(entry.name))
        except OSError:
            continue
    return out


def _kill_mid_run(
    lab: Lab, args: list[str], env: dict[str, str], out: Path, root: Path, salt: str, with_watcher: bool
) -> dict[str, Any]:
    """Start ``recap ARGS``, SIGKILL it (and its cluster's watcher) while calls are in flight."""
    ledger = out / "gateway" / "ledger.jsonl"
    size = ledger.stat().st_size if ledger.exists() else 0
    # no pipe: a process the killed driver started might hold its write end
    proc = lab.cli(args, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    started = wait_until(lambda: proc.poll() is not None or (ledger.exists() and ledger.stat().st_size > size), 300, 0.05)
    time.sleep(lab.rng(salt).uniform(0.5, 2.0))
    folder = next((f for f in root.iterdir() if f.name.startswith(f"{proc.pid}-")), None)
    watchers = _watcher_of(folder) if folder is not None else []
    if with_watcher:
        for pid in watchers:
            os.kill(pid, signal.SIGKILL)  # everything the driver started outside Ray: kill -9 of it all
    os.kill(proc.pid, signal.SIGKILL)  # the driver, as the OOM killer does
    proc.wait()
    term = terminal(out)
    finished = {r["episode_id"] for r in term.rows}
    return {
        "pid": proc.pid,
        "running": started and proc.returncode == -signal.SIGKILL,
        "folder": folder,
        "watchers": watchers,
        "done": {u: r["attempt"] for u, r in term.completed.items()},
        "cut": {k.rsplit("#", 1)[0] for k in _money(out)["reserved"]} - finished,
    }


def orphans(lab: Lab, units: int = 8) -> ScenarioResult:
    """SIGKILL ``recap run`` (its own local Ray) mid-run; then SIGKILL ``recap resume`` and its
    cluster's watcher; then ``recap resume`` to the end."""
    from pipeline.local_cluster import ENDED_FILE, OWNER_FILE, processes

    res = ScenarioResult("driver SIGKILL: orphan Ray processes + recap resume")
    res.begin_run()
    server = lab.server(latency_s=0.3, prefix_memory=0)
    base = lab.folder("orphans")
    out = base / "run"
    spec = base / "sweep.yaml"
    spec.write_text(sweep(out, fake_model(server.base_url), blocks(units), workers=2, llm_calls=6, extra="ray: {num_cpus: 2}\n"))
    root = Path(tempfile.mkdtemp(prefix="rr", dir="/tmp"))  # short: Ray's socket paths live under it
    env = lab.env(RECAP_RAY_TMP=str(root))
    try:
        # 1. the driver alone is killed: its cluster's watcher stops the cluster within seconds
        k1 = _kill_mid_run(lab, ["run", str(spec), "--progress", "off"], env, out, root, "orphans-1", with_watcher=False)
        res.check("first kill: calls were in flight", k1["running"] and k1["folder"] is not None, k1)
        res.check("the cluster has one watcher", len(k1["watchers"]) == 1, k1["watchers"])
        folder1 = k1["folder"]
        gone = wait_until(lambda: not processes(folder1) and (folder1 / ENDED_FILE).exists(), 30, 0.1)
        left1 = len(processes(folder1))
        log = (folder1 / "recap-watcher.log").read_text() if (folder1 / "recap-watcher.log").exists() else ""
        res.check("the watcher stopped the killed driver's cluster", gone and left1 == 0, (left1, log))
        res.check(
            "the watcher logged it",
            f"driver pid {k1['pid']} ended without shutting its Ray cluster down; stopped " in log,
            log,
        )
        # 2. the resume is killed together with its watcher: its cluster's processes stay
        k2 = _kill_mid_run(lab, ["resume", str(out), "--progress", "off"], env, out, root, "orphans-2", with_watcher=True)
        res.check("second kill (driver and watcher): calls were in flight", k2["running"] and k2["folder"] is not None, k2)
        time.sleep(3.0)  # what Ray's fate-sharing takes with the driver is gone by now
        left2 = len(processes(k2["folder"]))
        res.check("the processes of that cluster stay behind", left2 > 0, left2)
        # 3. the next resume stops them, says so, finishes
        resume = _cli(lab, ["resume", str(out), "--progress", "off"], env)
        text = _output(resume)
        res.check("the resume exits 0", resume.returncode == 0, f"exit {resume.returncode}: {_said(text)}")
        said = [line for line in text.splitlines() if line.startswith("recap: stopped ")]
        expected = (
            f"of the local Ray cluster left by driver pid {k2['pid']} (run {out}), which ended without shutting it down; "
            f"its Ray logs are in {k2['folder']}"
        )
        res.check("the resume says it stopped them, in one line", len(said) == 1 and expected in said[0], said or _said(text))
        time.sleep(1.0)
        after = {f.name: processes(f) for f in root.iterdir() if f.is_dir()}
        orphans_left = sum(len(p) for p in after.values())
        res.check("no process of any of the three clusters is left", orphans_left == 0, after)
        watchers_left = [p for f in root.iterdir() if f.is_dir() for p in _watcher_of(f)]
        res.check("no watcher is left", not watchers_left, watchers_left)
        records = sorted((f.name, (f / OWNER_FILE).exists(), (f / ENDED_FILE).exists()) for f in root.iterdir() if f.is_dir())
        res.check("the three clusters' records are marked ended", [r[1:] for r in records] == [(False, True)] * 3, records)
        term = terminal(out)
        res.check("lost 0, duplicated 0", not term.lost and term.duplicated == 0, (len(term.lost), term.duplicated))
        res.lost += len(term.lost)
        res.duplicated += term.duplicated
        repaid1, rerun1 = _repaid(out, k1["done"], k1["cut"])
        repaid2, rerun2 = _repaid(out, k2["done"], k2["cut"])
        res.check("no unit finished before a kill was run again", not (rerun1 | rerun2), sorted(rerun1 | rerun2))
        res.add_overspend(0.0)
        res.notes.append(
            f"orphan processes: driver killed {left1} (its watcher stopped them), driver + watcher killed {left2}, "
            f"after recap resume 0; calls re-paid {repaid1 + repaid2}, all of the "
            f"{len(k1['cut']) + len(k2['cut'])} attempts in flight at the kills"
        )
    finally:
        shutil.rmtree(root, ignore_errors=True)
    res.end_run()
    return res
