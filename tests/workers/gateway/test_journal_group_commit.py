"""Group commit of budget reservations: concurrent reservations share one fdatasync, and none is
answered before an fdatasync that covers its journal line has returned.

The fdatasync is wrapped to note how many bytes of the journal existed when each one started
(what it puts on disk); every answered reservation's line must end within such a prefix."""

from __future__ import annotations

import asyncio
import json
import os

import pytest

import workers.gateway.journal as journal_mod
from workers.gateway.journal import Journal, JournalError
from workers.gateway.ledger import JOURNAL_NAME, BudgetLedger, LocalBudget


@pytest.fixture
def synced_sizes(monkeypatch):
    """Journal bytes covered by each fdatasync so far (in call order)."""
    sizes: list[int] = []
    real = os.fdatasync

    def noting(fd: int) -> None:
        size = os.fstat(fd).st_size
        real(fd)
        sizes.append(size)

    monkeypatch.setattr(journal_mod.os, "fdatasync", noting)
    return sizes


def line_ends(path) -> dict[int, int]:
    """rid of each reserve line -> byte offset just past its newline."""
    ends, pos = {}, 0
    for line in path.read_bytes().splitlines(keepends=True):
        pos += len(line)
        entry = json.loads(line)
        if entry["op"] == "reserve":
            ends[entry["rid"]] = pos
    return ends


def test_concurrent_reservations_share_one_fdatasync_and_wait_for_it(tmp_path, synced_sizes):
    budget = LocalBudget(BudgetLedger(tmp_path, run_cap_usd=1.0))
    answered: list[tuple[int, int]] = []  # (rid, bytes on disk when it was answered)

    async def one(i: int) -> None:
        answer = await budget.begin(f"ep#{i}", "m", 1000 + i, None, "g:1")
        answered.append((answer["rid"], synced_sizes[-1]))

    async def go() -> None:
        await asyncio.gather(*[one(i) for i in range(20)])

    asyncio.run(go())
    assert len(synced_sizes) == 1  # twenty reservations, one fdatasync
    ends = line_ends(tmp_path / JOURNAL_NAME)
    assert sorted(rid for rid, _ in answered) == list(range(1, 21))
    assert all(ends[rid] <= on_disk for rid, on_disk in answered)
    # journal order is the order the callers reserved in, one rid each
    entries = [json.loads(x) for x in (tmp_path / JOURNAL_NAME).read_text().splitlines()]
    assert [(e["rid"], e["key"], e["pico"]) for e in entries] == [(i + 1, f"ep#{i}", 1000 + i) for i in range(20)]
    stats = budget.ledger.stats()
    assert (stats["open_reservations"], stats["journal_syncs"], stats["reserved_usd"]) == (20, 1, 20190 / 10**12)
    budget.ledger.close()


def test_a_reservation_after_a_commit_gets_its_own_fdatasync(tmp_path, synced_sizes):
    budget = LocalBudget(BudgetLedger(tmp_path))

    async def go() -> list[int]:
        rids = []
        for i in range(3):
            rids.append((await budget.begin(f"ep#{i}", "m", 10, None, "g:1"))["rid"])
            rids.append((await budget.reserve(f"ep#{i}", "m", 10, "g:1"))["rid"])
        return rids

    rids = asyncio.run(go())
    ends = line_ends(tmp_path / JOURNAL_NAME)
    assert rids == [1, 2, 3, 4, 5, 6] and len(synced_sizes) == 6
    assert [ends[rid] for rid in rids] == synced_sizes  # each answered right after its own sync
    budget.ledger.close()


def test_refusals_and_recorded_results_wait_for_no_fdatasync(tmp_path, synced_sizes):
    led = BudgetLedger(tmp_path, run_cap_usd=10**-9)  # 1000 pico
    budget = LocalBudget(led)

    async def go() -> list[dict]:
        first = await budget.begin("ep#0", "m", 600, None, "g:1")
        await budget.settle(first["rid"], 500, "ok", {"text": "hi"}, None, None)
        return [first, await budget.begin("ep#0", "m", 600, None, "g:1"), await budget.begin("ep#1", "m", 600, None, "g:1")]

    first, recorded, refused = asyncio.run(go())
    assert first == {"status": "reserved", "rid": 1} and len(synced_sizes) == 1
    assert recorded == {"status": "recorded", "served_from": "ledger", "result": {"text": "hi"}}
    assert refused["status"] == "refused" and refused["message"].startswith("run budget:")
    led.close()


def test_a_failed_fdatasync_answers_no_reservation_and_frees_the_cap(tmp_path, monkeypatch):
    led = BudgetLedger(tmp_path, run_cap_usd=10**-9)
    budget = LocalBudget(led)

    def broken(fd: int) -> None:
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(journal_mod.os, "fdatasync", broken)

    async def go() -> list:
        return await asyncio.gather(*[budget.begin(f"ep#{i}", "m", 400, None, "g:1") for i in range(2)], return_exceptions=True)

    results = asyncio.run(go())
    assert [type(r) for r in results] == [OSError, OSError]
    stats = led.stats()
    assert (stats["open_reservations"], stats["spent_pico"], stats["committed_usd"]) == (0, 0, 0.0)
    monkeypatch.undo()
    led.close()
    entries = [json.loads(x) for x in (tmp_path / JOURNAL_NAME).read_text().splitlines()]
    assert [(e["op"], e["rid"], e["pico"]) for e in entries] == [
        ("reserve", 1, 400),
        ("reserve", 2, 400),
        ("settle", 1, 0),
        ("settle", 2, 0),
    ]


def test_a_cancelled_waiter_releases_its_reservation_and_others_still_commit(tmp_path, synced_sizes):
    led = BudgetLedger(tmp_path)
    budget = LocalBudget(led)

    async def go() -> list:
        tasks = [asyncio.ensure_future(budget.begin(f"ep#{i}", "m", 100, None, "g:1")) for i in range(3)]
        await asyncio.sleep(0)  # all three reserved and waiting for the shared commit
        tasks[1].cancel()
        return await asyncio.gather(*tasks, return_exceptions=True)

    a, b, c = asyncio.run(go())
    assert (a, c) == ({"status": "reserved", "rid": 1}, {"status": "reserved", "rid": 3})
    assert isinstance(b, asyncio.CancelledError)
    assert len(synced_sizes) == 1 and led.reserved == 200 and set(led.open) == {1, 3}
    led.close()


def test_without_group_commit_each_reservation_fsyncs_inline(tmp_path, synced_sizes):
    budget = LocalBudget(BudgetLedger(tmp_path), group_commit=False)

    async def go() -> None:
        await asyncio.gather(*[budget.begin(f"ep#{i}", "m", 10, None, "g:1") for i in range(5)])

    asyncio.run(go())
    assert len(synced_sizes) == 5
    budget.ledger.close()


def test_journal_commit_counts_entries_and_refuses_after_close(tmp_path, synced_sizes):
    j = Journal(tmp_path / "j.jsonl")
    assert j.append({"op": "x"}) == 1 and j.append({"op": "y"}, sync=True) == 2
    assert (j.written, j.synced, synced_sizes) == (2, 2, [22])  # two 11-byte lines
    assert j.append({"op": "z"}) == 3 and j.synced == 2
    asyncio.run(j.commit())
    assert (j.synced, len(synced_sizes)) == (3, 2)
    asyncio.run(j.commit())  # nothing new: no fdatasync
    assert len(synced_sizes) == 2
    j.append({"op": "w"})
    j._fh.close()

    with pytest.raises(JournalError, match="closed before entry 4 was committed"):
        asyncio.run(j.commit())
    unsynced = Journal(tmp_path / "k.jsonl", fsync=False)
    unsynced.append({"op": "x"})
    asyncio.run(unsynced.commit())  # a journal without fsync has nothing to wait for
    assert unsynced.synced == 0
    unsynced.close()
