"""Test doubles for the pipeline's own tests: a tiny expert model and an in-process backend.

Used only where the pipeline must be exercised apart from the LLM gateway (the driver's
dispatch, retry and resume logic); the end-to-end tests go through the real gateway backend.
The expert follows ``hints["expert_plan"]`` (added by the episode worker), so a correct worker
makes every blocksworld episode succeed; a fixed latency makes episodes last long; a tiny budget
actor refuses calls past a cap, like the gateway's ledger, and can hold every call (``hold`` /
``release``) so that a test kills a worker mid-episode however loaded the machine is.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from typing import Any

from pipeline.backend import RateStats, Spend
from recap.llm import LLMError, LLMRequest, LLMResponse

PRICE_PER_CALL = 0.01


class TinyExpert:
    """Replies with the expert plan in the agent's format; costs PRICE_PER_CALL per call."""

    def __init__(self, latency_s: float = 0.0, budget: Any = None, model: str = "test/expert") -> None:
        self.latency_s = latency_s
        self.budget = budget
        self.model = model

    def complete(self, request: LLMRequest) -> LLMResponse:
        import ray

        if self.budget is not None:
            granted = ray.get(self.budget.reserve.remote(self.model, PRICE_PER_CALL))
            while granted is None:  # held: ask again
                time.sleep(0.02)
                granted = ray.get(self.budget.reserve.remote(self.model, PRICE_PER_CALL))
            if not granted:
                raise LLMError("budget", "run cap reached")
        if self.latency_s:
            time.sleep(self.latency_s)
        plan = list(request.hints.get("expert_plan") or [])
        style = request.hints.get("style")
        if style == "recap":
            reply: dict[str, Any] = {"think": "follow the plan", "subtasks": plan}
        elif style in ("cot", "standard"):
            reply = {"think": "plan", "actions": plan}
        else:
            reply = {"think": "next", "action": plan[0] if plan else "nothing"}
        return LLMResponse(
            text=json.dumps(reply),
            model=self.model,
            prompt_tokens=100,
            completion_tokens=10,
            cost_usd=PRICE_PER_CALL,
            test_double=True,
            token_count_source="estimate",
        )


class _Budget:
    """Reserve-before-call spend counter with an optional cap (the gateway ledger's contract)."""

    def __init__(self, cap: float | None = None) -> None:
        self.cap = cap
        self.spent: dict[str, float] = {}
        self.held = False

    def hold(self) -> None:
        """Hold every call (``reserve`` answers None, the caller asks again) until :meth:`release`."""
        self.held = True

    def release(self) -> None:
        self.held = False

    def reserve(self, model: str, amount: float) -> bool | None:
        if self.held:
            return None
        total = sum(self.spent.values())
        if self.cap is not None and total + amount > self.cap + 1e-12:
            return False
        self.spent[model] = self.spent.get(model, 0.0) + amount
        return True

    def set_cap(self, cap: float | None) -> None:
        self.cap = cap

    def totals(self) -> dict[str, float]:
        return dict(self.spent)


@dataclass
class TinyFactory:
    latency_s: float
    budget: Any
    labels: dict[str, str] = field(default_factory=dict)
    writes_llm_calls: bool = False

    def client(self, model: str) -> TinyExpert:
        return TinyExpert(self.latency_s, self.budget, model=self.labels.get(model, model))


class TinyBackend:
    """A ModelBackend over TinyExpert; spend comes from the budget actor (by model label)."""

    writes_llm_calls = False

    def __init__(self, latency_s: float = 0.0, initial_spend: float = 0.0) -> None:
        self.latency_s = latency_s
        self.initial_spend = initial_spend
        self.budget: Any = None

    def start(self, **_: Any) -> None:
        import ray

        self.budget = ray.remote(num_cpus=0)(_Budget).remote()
        if self.initial_spend:
            ray.get(self.budget.reserve.remote("earlier", self.initial_spend))

    def factory(self) -> TinyFactory:
        return TinyFactory(self.latency_s, self.budget)

    def spend(self) -> Spend:
        import ray

        totals = ray.get(self.budget.totals.remote())
        return Spend(sum(totals.values()), totals)

    def rate_stats(self) -> dict[str, RateStats]:
        return {}

    def set_run_cap(self, usd: float | None) -> None:
        import ray

        ray.get(self.budget.set_cap.remote(usd))

    def flush(self) -> None:
        pass

    def close(self) -> None:
        import ray

        if self.budget is not None:
            ray.kill(self.budget)
