"""The served models' cost (pipeline/serving/cost.py): replica time charged to the ledger as it
accrues, at the replicas x hourly price, each charge a reservation settled at once under the
model's name; a charge the ledger refuses stops the run and is not counted."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest

from pipeline.serving.cost import ServeCost
from pipeline.serving.engines import ServePlan
from pipeline.serving.service import Served

PICO = 10**12


class FakeBudget:
    """The BudgetActor's begin/settle as a ledger with a run cap (pico-dollars)."""

    def __init__(self, cap_pico: int) -> None:
        self.cap, self.spent, self.next_rid = cap_pico, 0, 0
        self.log: list[tuple[Any, ...]] = []
        self.begin = SimpleNamespace(remote=self._begin)
        self.settle = SimpleNamespace(remote=self._settle)

    def _begin(self, key, name, pico, cache_key, owner):
        self.log.append(("begin", key, name, pico, owner))
        if self.spent + pico > self.cap:
            return {"status": "refused", "message": "run cap $1.00 would be passed"}
        self.next_rid += 1
        return {"status": "reserved", "rid": self.next_rid}

    def _settle(self, rid, pico, status, *rest):
        self.spent += pico
        self.log.append(("settle", rid, pico, status))


def plan(replicas: int, per_hour: float) -> ServePlan:
    return ServePlan("m", "test-double", "offline/expert", None, replicas, 0, 0.05, 2, 60.0, {}, per_hour)


@pytest.fixture(autouse=True)
def _no_ray(monkeypatch):
    import ray

    monkeypatch.setattr(ray, "get", lambda x: x)


def test_replica_time_is_charged_as_it_accrues_and_a_refused_charge_stops_the_run():
    budget = FakeBudget(cap_pico=1 * PICO)
    events: list[tuple[str, dict]] = []
    stops: list[str] = []
    served = {"m": Served(plan(2, 360.0), "recap-r-0", "/recap/r/0", "http://x/v1", started_at=1000.0)}
    cost = ServeCost("r", served, budget, lambda k, **d: events.append((k, d)), stops.append, every_s=5.0)
    cost.tick(now=1002.0)  # the first tick charges: 2 replicas x 2 s x $0.10/s = $0.40
    cost.tick(now=1004.0)  # within every_s: nothing
    assert budget.log == [("begin", "serve:r:m:0", "m", 400_000_000_000, "serve:m"), ("settle", 1, 400_000_000_000, "ok")]
    cost.tick(now=1007.0)  # 5 s more: $1.00 would pass the $1 cap with the $0.40 spent
    assert budget.log[-1] == ("begin", "serve:r:m:1", "m", PICO, "serve:m")
    assert stops == ["serving m would pass a cap (run cap $1.00 would be passed)"]
    assert events == [("serve_cost", {"severity": "warning", "model": "m", "refused_usd": 1.0, "reason": stops[0]})]
    cost.tick(now=1020.0)  # refused once: no more charges (the run stops starting units)
    assert len(budget.log) == 3 and budget.spent == 400_000_000_000
    cost.close()
    assert events[-1][0] == "serve_cost"
    assert events[-1][1]["usd"] == pytest.approx(0.4) and events[-1][1]["replica_hours"] > 2 * 20 / 3600


def test_a_model_served_without_a_price_is_never_charged():
    budget = FakeBudget(cap_pico=PICO)
    events: list[tuple[str, dict]] = []
    served = {"m": Served(plan(2, 0.0), "recap-r-0", "/recap/r/0", "http://x/v1", started_at=0.0)}
    cost = ServeCost("r", served, budget, lambda k, **d: events.append((k, d)), lambda why: None)
    cost.charge(now=3600.0)
    cost.close()
    assert budget.log == []
    ((kind, detail),) = events
    assert (kind, detail["usd"], detail["replicas"]) == ("serve_cost", 0.0, 2) and detail["replica_hours"] >= 2.0
