"""A single gateway spending a dollar lease (``LeasedBudget(keep_worst=...)``, what every gateway of
a pipeline run does): no round trip to the authority per call, the same refusals as a gateway that
reserves each call at the authority, exact spend, and a crash that charges at most ``keep_worst``
worst cases beyond the calls in flight. Without Ray (the authority in-process)."""

from __future__ import annotations

import asyncio

from workers.gateway.ledger import BudgetLedger, LocalBudget
from workers.gateway.quota import LeaseLedger, LocalQuota, QuotaBook
from workers.gateway.shard import LeasedBudget

W = 10**9  # a call's worst case, pico-USD
COST = W // 3  # what it really costs
KEEP = 4


def _quota(tmp_path, run_cap_usd: float | None = None) -> LocalQuota:
    return LocalQuota(LeaseLedger(tmp_path, run_cap_usd=run_cap_usd, fsync=False, lease_calls=4), QuotaBook({}), owned=False)


async def _serve_until_refused(budget, limit: int = 10_000) -> int:
    """Calls one after another (begin, settle at COST) until the budget refuses one; how many were served."""
    for i in range(limit):
        ans = await budget.begin(f"e-1#{i}", "m", W, None, "m:one")
        if ans["status"] != "reserved":
            assert ans["refusal"]["scope"] == "run"
            return i
        await budget.settle(ans["rid"], COST, "ok", {"text": str(i)}, None, None)
    raise AssertionError("never refused")


def test_a_leased_gateway_is_refused_at_the_same_call_as_one_reserving_each_call(tmp_path):
    cap = (100 * COST + W - 1) / 10**12  # the 101st call's worst case does not fit

    async def plain() -> int:
        budget = LocalBudget(BudgetLedger(tmp_path / "plain", run_cap_usd=cap, fsync=False))
        try:
            return await _serve_until_refused(budget)
        finally:
            await budget.close()

    async def leased() -> tuple[int, dict, dict]:
        quota = _quota(tmp_path / "leased", cap)
        budget = LeasedBudget(quota, "m", "m", keep_worst=KEEP, report_s=60)
        await budget.adopt_orphans("m", "")
        served = await _serve_until_refused(budget)
        await budget.close()
        return served, dict(budget.counts), {**quota.ledger.stats(), "requests": dict(quota.requests)}

    served, counts, stats = asyncio.run(leased())
    assert served == asyncio.run(plain()) == 100
    # the cap was reached exactly, every call recorded at its cost, nothing left reserved
    assert (stats["spent_pico"], stats["reserved_usd"], stats["open_reservations"]) == (100 * COST, 0, 0)
    assert stats["recorded_results"] == 100
    # most calls were served out of the lease; only the last ones, once the headroom was below a
    # grant of one worst case, went to the authority one by one
    assert counts["local"] > 80 and counts["remote"] == stats["requests"]["reserve"]  # the refused one too
    assert stats["requests"]["begin"] == 0 and stats["requests"]["settle"] == counts["remote"] - 1


def test_a_crashed_leased_gateway_is_charged_at_most_keep_worst_cases_beyond_its_calls_in_flight(tmp_path):
    async def go() -> tuple[int, int, dict]:
        quota = _quota(tmp_path)  # uncapped: grants are still a few worst cases, never more
        dead = LeasedBudget(quota, "m", "m", keep_worst=KEEP, report_s=0.02)
        await dead.adopt_orphans("m", "")
        answers = await asyncio.gather(*[dead.begin(f"e-{i}#0", "m", W, None, "") for i in range(16)])
        assert all(a["status"] == "reserved" for a in answers)
        assert quota.ledger.lease_stats()["leased_usd"] * 10**12 <= (16 + 4) * W
        for a in answers[:15]:  # 15 calls end, one stays in flight
            await dead.settle(a["rid"], COST, "ok", None, None, None)
        await asyncio.sleep(0.3)  # report ticks: the calls are written, the unused lease trimmed
        assert dead._loop_task is not None
        dead._loop_task.cancel()  # the gateway process dies: no more reports, the lease stays open
        reborn = LeasedBudget(quota, "m", "m", keep_worst=KEEP)
        adopted = await reborn.adopt_orphans("m", "")
        await reborn.close()
        return adopted, dead.counts["remote"], quota.ledger.stats()

    adopted, remote, stats = asyncio.run(go())
    assert adopted == 1 and remote == 0  # one open lease charged; not one call went to the authority
    # 15 calls at their cost, the one in flight at its worst case, and at most KEEP unused worst cases
    assert 15 * COST + W <= stats["spent_pico"] <= 15 * COST + W + KEEP * W
    assert (stats["reserved_usd"], stats["open_reservations"]) == (0, 0)
