"""A served model's adaptive in-flight limit (workers/gateway/adaptive.py): the exact limits for
given latency, queue and error series, and the gateway's admission applying them."""

from __future__ import annotations

import asyncio

import pytest

from tests.workers.gateway.adaptive_admission import adaptive_controller
from workers.gateway.adaptive import AdaptiveLimit, LimitChange


def _slots(limit: AdaptiveLimit, latencies: list[float]) -> tuple[list[int], list[LimitChange]]:
    slots, changes = [], []
    for latency in latencies:
        change = limit.observe(latency)
        if change is not None:
            changes.append(change)
        slots.append(limit.slots)
    return slots, changes


def test_latency_over_twice_the_baseline_halves_once_a_round_then_the_limit_grows_back_one_slot_a_round():
    limit = AdaptiveLimit(floor=2, ceiling=8)
    slots, changes = _slots(limit, [1.0, 1.0, 1.0, 3.0, 3.0, 3.0, 3.0, 3.0, 3.0, 1.0, 1.0, 1.0, 1.0, 1.0])
    # 8 -> 4 at the first slow call; the next 3 slow calls were admitted under 8: one round (4
    # calls) before 4 -> 2; at the floor a slow call changes nothing; then +1/limit a call:
    # 2.5, 2.9, 3.2448 (3 slots), 3.5530, 3.8345 (3.834462)
    assert slots == [8, 8, 8, 4, 4, 4, 4, 2, 2, 2, 2, 3, 3, 3]
    assert changes == [
        LimitChange(8, 4, "latency", 3.0, 1.0, None),
        LimitChange(4, 2, "latency", 3.0, 1.0, None),
        LimitChange(2, 3, "recovered", 1.0, 1.0, None),
    ]
    assert limit.limit == pytest.approx(3.834462, abs=1e-6)


def test_a_reported_queue_decreases_the_limit_whatever_the_latency_never_below_the_floor():
    limit = AdaptiveLimit(floor=3, ceiling=4)
    assert limit.observe(1.0, queue=2) == LimitChange(4, 3, "queue", 1.0, 1.0, 2)
    assert limit.observe(1.0, queue=0) is None and limit.limit == pytest.approx(3 + 1 / 3)
    for _ in range(3):  # a round of 3 calls, then the queue again: 3.33 x 0.5 is under the floor
        limit.observe(1.0, queue=5)
    assert (limit.limit, limit.slots) == (3.0, 3)


def test_capacity_errors_decrease_the_limit_once_a_round_and_a_bad_request_does_not():
    limit = AdaptiveLimit(floor=1, ceiling=6)
    assert limit.failed("bad_request") is None and limit.failed("context_length") is None and limit.slots == 6
    assert limit.failed("server_error") == LimitChange(6, 3, "error", None, None, None)
    assert limit.failed("server_error") is None  # the other calls of that round: no second halving
    limit.observe(1.0)  # 3.3333
    limit.observe(1.0)  # 3.6333
    assert limit.failed("timeout") == LimitChange(3, 1, "error", None, 1.0, None)  # 1.8167: one slot
    assert limit.limit == pytest.approx(1.816667, abs=1e-6)


def test_the_baseline_is_the_least_latency_of_the_recent_calls():
    old = AdaptiveLimit(floor=1, ceiling=4, baseline_samples=3)
    assert _slots(old, [1.0, 2.0, 2.0, 2.0, 2.1]) == ([4, 4, 4, 4, 4], [])  # 1.0 has left: baseline 2.0
    assert old.baseline_s == 2.0
    kept = AdaptiveLimit(floor=1, ceiling=4, baseline_samples=100)
    assert _slots(kept, [1.0, 2.0, 2.0, 2.0, 2.1]) == ([4, 4, 4, 4, 2], [LimitChange(4, 2, "latency", 2.1, 1.0, None)])


@pytest.mark.parametrize("floor, ceiling", [(0, 4), (5, 4)])
def test_a_floor_outside_one_to_the_ceiling_is_refused(floor, ceiling):
    with pytest.raises(ValueError, match="floor"):
        AdaptiveLimit(floor=floor, ceiling=ceiling)


def test_admission_keeps_no_more_calls_in_flight_than_the_adapted_limit():
    now = [0.0]
    changes: list[LimitChange] = []

    async def run():
        ac = adaptive_controller(now, changes, floor=1, ceiling=4)
        first = [await ac.acquire(10) for _ in range(4)]
        now[0] = 1.0
        ac.release(first[0], "ok")  # 1 s: the baseline
        now[0] = 3.5
        ac.release(first[1], "ok")  # 3.5 s: congested, 4 -> 2
        assert (ac.limit, ac.stats()["concurrency_limit"]) == (2.0, 2.0)
        waiter = asyncio.ensure_future(ac.acquire(10))
        await asyncio.sleep(0.01)
        assert ac.active == 2 and not waiter.done()  # two in flight under a limit of two
        now[0] = 4.0
        ac.release(first[2], "ok")  # 4 s, still slow, but within the round admitted under 4
        second = await waiter
        assert ac.active == 2 and ac.limit == 2.0
        ac.release(first[3], "server_error")  # a replica lost: a round has passed, 2 -> 1
        assert ac.limit == 1.0
        now[0] = 5.0
        ac.release(second, "ok")  # admitted at 4: 1 s, +1/1
        assert ac.limit == 2.0 and ac.adaptive is not None
        ac.set_limits(max_concurrency=3)  # a new ceiling (fewer replicas): the limit restarts there
        assert (ac.limit, ac.adaptive.ceiling, ac.adaptive.limit) == (3.0, 3, 3.0)

    asyncio.run(run())
    assert changes == [
        LimitChange(4, 2, "latency", 3.5, 1.0, None),
        LimitChange(2, 1, "error", None, 1.0, None),
        LimitChange(1, 2, "recovered", 1.0, 1.0, None),
    ]


def test_latency_is_counted_per_output_token_when_the_reply_size_is_known():
    limit = AdaptiveLimit(floor=1, ceiling=4)
    # 1 s for 10 tokens, then 20 s for 250 tokens: 0.1 and 0.08 s a token, not congested
    assert limit.observe(1.0, output_tokens=10) is None and limit.observe(20.0, output_tokens=250) is None
    assert limit.baseline_s == 0.08
    # 2 s for 10 tokens: 0.2 s a token, over twice the 0.08 baseline
    assert limit.observe(2.0, output_tokens=10) == LimitChange(4, 2, "latency", 0.2, 0.08, None)
    # no size: 5 s as is (slow, but within the round of the last decrease: no change)
    assert limit.observe(5.0, output_tokens=0) is None and (limit.baseline_s, limit.slots) == (0.08, 2)
