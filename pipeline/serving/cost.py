"""What a served model costs: the replica-hours it holds, charged to the run's ledger as they accrue.

Why the ledger: a served model's tokens cost nothing by themselves (its price table entry is 0);
what is paid is the time its replicas hold their GPUs (``prices: {gpu_hour: X}``: X per GPU-hour,
times the GPUs of a replica) or their node (``{replica_hour: X}``). That time is charged to the
run's budget ledger - the one that holds the run and model caps - every :data:`CHARGE_EVERY_S`
while the session runs and once more when serving stops, as a reservation settled at once
under the model's name (call key ``serve:<run id>:<model>:<n>``, owner ``serve:<model>``).
So the run's spend, ``recap show`` and the caps include it; a charge the ledger refuses (it
would pass a cap) stops the run from starting units (:meth:`CapPolicy.stop_run`), and the
serving stops with the session.

Attribution: each ``serve_cost`` event carries the model's serving dollars so far and, at the
end, the dollars per token of its calls; :func:`attribution_sql` gives each ``llm_calls`` row its
share by its tokens (``prompt_tokens + completion_tokens`` over the model's total).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from pipeline.serving.service import Served
from workers.llm.pricing import pico_to_usd, usd_to_pico

#: seconds between two charges while the session runs
CHARGE_EVERY_S = 5.0


@dataclass
class ModelCharge:
    """What one served model was charged so far."""

    until: float
    usd: float = 0.0
    held_s: float = 0.0
    charges: int = 0
    refused: bool = False


@dataclass
class ServeCost:
    """The charges of the run's served models to its ledger (``budget``: the BudgetActor handle)."""

    run_id: str
    served: dict[str, Served]
    budget: Any
    event: Callable[..., None]
    #: called with one line when a charge is refused (the run stops starting units)
    stop_run: Callable[[str], None]
    every_s: float = CHARGE_EVERY_S
    charged: dict[str, ModelCharge] = field(default_factory=dict)
    _last: float = 0.0

    def __post_init__(self) -> None:
        for label, s in self.served.items():
            self.charged[label] = ModelCharge(until=s.started_at)

    def tick(self, now: float | None = None) -> None:
        """Charge what accrued since the last charge, at most every ``every_s``."""
        now = time.time() if now is None else now
        if now - self._last < self.every_s:
            return
        self._last = now
        self.charge(now)

    def charge(self, now: float | None = None) -> None:
        """Charge every served model's replica time up to ``now``."""
        import ray  # lazy: Ray loads only where a session uses it

        now = time.time() if now is None else now
        for label, s in self.served.items():
            c = self.charged[label]
            dt = max(0.0, now - c.until)
            usd = s.plan.replicas * s.plan.usd_per_replica_hour * dt / 3600.0
            pico = usd_to_pico(usd)
            c.held_s += dt
            c.until = now
            if pico <= 0 or c.refused:
                continue
            key = f"serve:{self.run_id}:{label}:{c.charges}"
            answer = ray.get(self.budget.begin.remote(key, label, pico, None, f"serve:{label}"))
            if answer.get("status") != "reserved":
                c.refused = True
                why = f"serving {label} would pass a cap ({answer.get('message', 'refused')})"
                self.event("serve_cost", severity="warning", model=label, refused_usd=usd, reason=why)
                self.stop_run(why)
                continue
            ray.get(self.budget.settle.remote(answer["rid"], pico, "ok", None, None, None))
            c.usd += pico_to_usd(pico)  # what the ledger holds, to the pico-dollar
            c.charges += 1

    def close(self, tokens: dict[str, int] | None = None) -> None:
        """The last charge (serving stopped now) and one ``serve_cost`` event per model: its
        replica- and GPU-hours and dollars (and, given its calls' ``tokens``, dollars per token)."""
        self.charge()
        for label, s in self.served.items():
            c = self.charged[label]
            replica_hours = s.plan.replicas * c.held_s / 3600.0
            per_token: dict[str, Any] = {}
            if tokens is not None:
                n = tokens.get(label, 0)
                per_token = {"tokens": n, "usd_per_token": (c.usd / n) if n else None}
            self.event(
                "serve_cost",
                model=label,
                engine=s.plan.engine,
                replicas=s.plan.replicas,
                gpus_per_replica=s.plan.gpus,
                held_s=c.held_s,
                replica_hours=replica_hours,
                gpu_hours=replica_hours * s.plan.gpus,
                usd=c.usd,
                usd_per_replica_hour=s.plan.usd_per_replica_hour,
                **per_token,
            )


def attribution_sql(model_name: str) -> str:
    """A query over a run's tables (``recap sql``): each ``llm_calls`` row of served model
    ``model_name`` with its share of the serving cost by its tokens (``serving_usd``)."""
    name = model_name.replace("'", "''")
    return f"""
with cost as (
  select sum(cast(detail->>'usd' as double)) as usd from events
  where kind = 'serve_cost' and detail->>'model' = '{name}' and detail->>'held_s' is not null
), calls as (
  select call_key, episode_id, prompt_tokens + completion_tokens as tokens from llm_calls where model_name = '{name}'
)
select call_key, episode_id, tokens,
       case when sum(tokens) over () > 0 then (select usd from cost) * tokens / sum(tokens) over () else 0 end as serving_usd
from calls order by call_key
"""
