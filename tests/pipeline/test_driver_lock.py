"""The driver lock (no Ray): taken atomically (flock on an open file, held for the session), so
drivers started at the same moment get exactly one winner; a lock whose driver died - however
it died - is free; a live holder is named in a one-line refusal."""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import signal
import socket
import threading
import time
from pathlib import Path

import pytest

from pipeline.driver import prepare
from pipeline.errors import RunFolderError
from pipeline.spec import parse_spec
from pipeline.store import LOCK_FILE, RunStore

SPEC = """run: locked
output: {out}
models: [{{model: offline/expert}}]
methods: [{{method: react}}]
environments: [{{benchmark: blocksworld, tasks: ["3"]}}]
"""


def _race_threads(folder: Path, n: int) -> list[RunStore]:
    """``n`` threads call acquire_lock at once; the stores that got it (still held)."""
    barrier = threading.Barrier(n)
    winners: list[RunStore] = []
    refusals: list[str] = []
    lock = threading.Lock()

    def go() -> None:
        store = RunStore(folder)
        barrier.wait()
        try:
            store.acquire_lock(wait_s=0)
        except RunFolderError as exc:
            with lock:
                refusals.append(str(exc))
            return
        with lock:
            winners.append(store)

    threads = [threading.Thread(target=go) for _ in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(winners) + len(refusals) == n
    assert all("is in use by another driver" in r and "\n" not in r for r in refusals)
    return winners


def test_50_synchronised_trials_with_threads_have_exactly_one_winner_each(tmp_path):
    for trial in range(50):
        folder = tmp_path / f"t{trial}"
        if trial % 2:
            folder.mkdir()
            (folder / LOCK_FILE).write_text(json.dumps({"pid": 999999999, "host": socket.gethostname()}))  # stale
        winners = _race_threads(folder, 8)
        assert len(winners) == 1, f"trial {trial}: {len(winners)} winners"
        assert RunStore(folder).lock_holder()["pid"] == os.getpid()
        winners[0].release_lock()
        assert RunStore(folder).lock_holder() is None


def _contender(folder: str, barrier, results, hold) -> None:
    store = RunStore(folder)
    barrier.wait()
    try:
        store.acquire_lock(wait_s=0)
    except RunFolderError:
        results.put("refused")
        return
    results.put("won")
    hold.wait(30)  # keep it while the others try
    store.release_lock()


def test_synchronised_trials_with_processes_have_exactly_one_winner_each(tmp_path):
    ctx = mp.get_context("fork")
    for trial in range(20):
        folder = tmp_path / f"p{trial}"
        barrier, results, hold = ctx.Barrier(4), ctx.Queue(), ctx.Event()
        procs = [ctx.Process(target=_contender, args=(str(folder), barrier, results, hold)) for _ in range(4)]
        for p in procs:
            p.start()
        got = sorted(results.get(timeout=30) for _ in procs)
        hold.set()
        for p in procs:
            p.join(30)
        assert got == ["refused", "refused", "refused", "won"], f"trial {trial}: {got}"
        assert RunStore(folder).lock_holder() is None  # released, or its holder exited


def _hold_forever(folder: str, ready) -> None:
    RunStore(folder).acquire_lock()
    ready.set()
    time.sleep(600)


def test_a_killed_driver_releases_the_lock_and_a_live_one_is_named(tmp_path):
    ctx = mp.get_context("fork")
    ready = ctx.Event()
    p = ctx.Process(target=_hold_forever, args=(str(tmp_path), ready))
    p.start()
    assert ready.wait(30)
    holder = RunStore(tmp_path).lock_holder()
    assert holder is not None and holder["pid"] == p.pid
    with pytest.raises(RunFolderError) as err:
        RunStore(tmp_path).acquire_lock(wait_s=0.2)
    assert str(err.value) == (
        f"run folder {tmp_path} is in use by another driver (pid {p.pid} on {socket.gethostname()}); "
        "wait for it to finish (a driver that dies releases the lock by itself)"
    )
    with pytest.raises(RunFolderError, match="in use by another driver"):
        RunStore(tmp_path).check_unlocked()
    os.kill(p.pid, signal.SIGKILL)
    p.join(30)
    assert (tmp_path / LOCK_FILE).exists()  # the file stays behind ...
    assert RunStore(tmp_path).lock_holder() is None  # ... but nobody holds it: stale
    store = RunStore(tmp_path)
    store.acquire_lock(wait_s=0)
    store.release_lock()
    assert not (tmp_path / LOCK_FILE).exists()


def test_a_stale_lock_file_of_a_live_unrelated_pid_is_free(tmp_path):
    # the pid in the file is alive (this test process) but nobody holds the flock: pid reuse
    (tmp_path / LOCK_FILE).write_text(json.dumps({"pid": os.getpid(), "host": socket.gethostname()}))
    assert RunStore(tmp_path).lock_holder() is None
    store = RunStore(tmp_path)
    store.acquire_lock(wait_s=0)
    assert json.loads((tmp_path / LOCK_FILE).read_text())["pid"] == os.getpid()
    with pytest.raises(RunFolderError):
        RunStore(tmp_path).acquire_lock(wait_s=0)
    store.release_lock()


def test_prepare_refuses_a_folder_a_driver_holds_even_before_it_wrote_run_json(tmp_path):
    out = tmp_path / "run"
    holder = RunStore(out)
    holder.acquire_lock()  # a driver that has just started: its lock is all the folder holds
    text = SPEC.format(out=out)
    with pytest.raises(RunFolderError, match="is in use by another driver"):
        prepare(parse_spec(text), text)
    holder.release_lock()
    out.mkdir(exist_ok=True)
    (out / LOCK_FILE).write_text("{}")  # a driver that crashed before it wrote run.json
    assert prepare(parse_spec(text), text).identity is None
