"""The driver's view of the model side: clients for the workers, spend, rate statistics.

Why an interface: the driver must not care whether calls go through the Ray LLM gateway (the
product) or a small in-process test double (the pipeline's own tests). A backend gives the
workers a picklable :class:`workers.episode_worker.ClientFactory`, tells the driver what has
been spent (run total and per model) and how close each model is to its rate limits, and says
whether it writes the ``llm_calls`` table itself.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

from workers.episode_worker import ClientFactory


@dataclass(frozen=True)
class Spend:
    """Dollars spent so far in the run: the run total and the spend of each model, keyed by the
    model's name in the sweep."""

    total_usd: float = 0.0
    by_model: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class RateStats:
    """One model's recent use against its limits (None: no limit / unknown)."""

    rpm: float | None = None
    rpm_limit: float | None = None
    tpm: float | None = None
    tpm_limit: float | None = None
    in_flight: int | None = None
    #: epoch seconds until which a provider's Retry-After pauses this model (None: not paused)
    paused_until: float | None = None


class ModelBackend(Protocol):
    """What the driver needs of a model backend (the gateway, or a test double): start it, hand the
    workers a client factory, report spend and rate use, set the run cap, flush and close.
    ``writes_llm_calls`` True: the backend writes the ``llm_calls`` rows itself, so the workers do
    not."""

    writes_llm_calls: bool

    def start(self, *, run_dir: str, run_id: str, runtime_env: dict[str, Any] | None, node_id: str | None) -> None:
        """Start whatever serves the models (called after ray.init, before any worker)."""

    def factory(self) -> ClientFactory: ...

    def spend(self) -> Spend: ...

    def rate_stats(self) -> dict[str, RateStats]: ...

    def set_run_cap(self, usd: float | None) -> None: ...

    def flush(self) -> None:
        """Write whatever the backend buffers (its llm_calls/events parts)."""

    def close(self) -> None: ...
