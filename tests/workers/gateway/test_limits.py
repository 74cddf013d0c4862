"""Admission control without a server: windows, AIMD, Retry-After pause, pause/resume."""

from __future__ import annotations

import asyncio
import time

import pytest

from workers.gateway.limits import AdmissionController, AdmissionError, SlidingWindow


def test_sliding_window_counts_entries_until_a_window_after_their_response():
    w = SlidingWindow(limit=10, span_s=6.0)
    a = w.add(4, now=0.0)
    b = w.add(4, now=1.0)
    assert w.wait_s(2, now=2.0) == 0.0
    assert w.wait_s(3, now=2.0) == 6.0  # both in flight: no known end (a finish wakes earlier)
    w.finish(a, now=0.5)
    w.finish(b, now=3.0)
    assert w.wait_s(3, now=4.0) == 2.5  # a's window ends at 0.5 + 6
    assert w.wait_s(7, now=4.0) == 5.0  # b's too: 3 + 6
    e = w.add(2, now=4.0)
    w.finish(e, now=4.5, amount=1)  # actual usage was lower than the estimate
    assert w.usage(now=4.5) == (3, 9)
    assert w.usage(now=7.0) == (2, 5)


def test_a_window_follows_the_end_of_each_entrys_window_not_the_admission_order():
    """Responses arrive out of admission order (and a test's clock may go back): the room a window
    finds, its pruning and a late usage correction follow each entry's own end, and a pruned
    entry's correction no longer counts."""
    w = SlidingWindow(limit=10, span_s=6.0)
    a, b, c = w.add(3, now=0.0), w.add(3, now=0.1), w.add(3, now=0.2)
    w.finish(c, now=1.0)
    w.finish(a, now=3.0)
    w.finish(b, now=2.0)  # before a's end although it came back later
    assert w.wait_s(4, now=3.0) == 4.0  # c's window ends at 1 + 6
    assert w.wait_s(7, now=3.0) == 5.0  # then b's, at 2 + 6
    assert w.wait_s(10, now=3.0) == 6.0  # then a's, at 3 + 6
    assert w.usage(now=7.0) == (2, 6)  # c left
    assert w.usage(now=8.0) == (1, 3)  # b too
    w.finish(b, now=8.0, amount=1)  # a late correction of a pruned entry: not counted
    assert w.usage(now=8.0) == (1, 3)
    w.remove(a)
    assert w.usage(now=8.0) == (0, 0)


def test_admission_anchor_counts_from_admission():
    w = SlidingWindow(limit=10, span_s=6.0, anchor="admission")
    w.add(4, now=0.0)
    w.add(4, now=1.0)
    assert w.wait_s(3, now=2.0) == 4.0  # the entry of t=0 leaves at t=6


def _controller(**kw) -> AdmissionController:
    args = dict(rpm=None, tpm=None, window_s=60.0, pad_s=0.0, max_concurrency=8, rate_limit_default_wait_s=0.3)
    args.update(kw)
    return AdmissionController(**args)


def test_aimd_halves_once_per_pause_and_grows_back_additively():
    async def run():
        ac = _controller()
        tickets = [await ac.acquire(10) for _ in range(4)]
        ac.release(tickets[0], "rate_limit", retry_after_s=0.2)
        ac.release(tickets[1], "rate_limit", retry_after_s=0.2)  # same pause: no second halving
        assert ac.limit == 4.0 and ac.shrinks == 1
        ac.release(tickets[2], "server_error")
        assert ac.limit == 4.0  # 5xx does not shrink
        t0 = time.monotonic()
        t = await ac.acquire(10)  # waits for the Retry-After pause
        assert time.monotonic() - t0 >= 0.18
        ac.release(t, "ok")
        assert ac.limit == 4.25
        ac.release(tickets[3], "ok")
        assert ac.limit == pytest.approx(4.25 + 1 / 4.25)

    asyncio.run(run())


def test_requests_bigger_than_the_token_window_are_refused():
    async def run():
        ac = _controller(tpm=100)
        with pytest.raises(AdmissionError, match="needs 101 tokens"):
            await ac.acquire(101)

    asyncio.run(run())


def test_concurrency_limit_and_pause_hold_new_attempts():
    async def run():
        ac = _controller(max_concurrency=2)
        a, b = await ac.acquire(1), await ac.acquire(1)
        third = asyncio.ensure_future(ac.acquire(1))
        await asyncio.sleep(0.05)
        assert not third.done()
        ac.release(a, "ok")
        c = await asyncio.wait_for(third, 1.0)
        ac.pause()
        ac.release(b, "ok")
        ac.release(c, "ok")
        held = asyncio.ensure_future(ac.acquire(1))
        await asyncio.sleep(0.05)
        assert not held.done() and ac.stats()["paused"] is True
        ac.resume()
        ac.release(await asyncio.wait_for(held, 1.0), "ok")
        assert ac.active == 0

    asyncio.run(run())


def test_rpm_window_paces_admissions():
    async def run():
        ac = _controller(rpm=3, window_s=0.5, pad_s=0.05)
        t0 = time.monotonic()
        times = []
        for _ in range(7):
            t = await ac.acquire(1)
            times.append(t.admitted_at - t0)
            ac.release(t, "ok")
        # 3 at once, 3 more once the first leave the 0.55 s window, then the 7th
        assert max(times[:3]) < 0.1
        assert 0.54 <= min(times[3:6]) and max(times[3:6]) < 0.8
        assert times[6] >= 1.09

    asyncio.run(run())


def test_a_window_without_a_limit_keeps_only_its_span():
    """Nothing asks an unlimited window for room, so it must drop what left its span on its own:
    it kept every entry of the run (the gateway's memory grew with every call, and ``finish``
    scanned them all)."""
    w = SlidingWindow(limit=None, span_s=1.0)
    for i in range(10_000):  # 100 calls a second for 100 s
        w.finish(w.add(3, now=i / 100), now=i / 100)
    assert len(w._entries) < 300
    assert w.usage(now=99.99) == (100, 300)  # the responses of the last second: t = 99.00 .. 99.99


def test_an_unlimited_deployment_keeps_a_bounded_window():
    now = [0.0]

    async def run():
        ac = _controller(rpm=None, tpm=None, window_s=1.0, clock=lambda: now[0])
        for i in range(5_000):
            now[0] = i / 50
            ac.release(await ac.acquire(120), "ok", actual_tokens=100)
        return ac

    ac = asyncio.run(run())
    assert len(ac.requests._entries) < 200 and len(ac.tokens._entries) < 200
    stats = ac.stats()
    assert (stats["window_requests"], stats["window_tokens"]) == (50, 5000)  # the last second: 50 calls of 100 tokens
