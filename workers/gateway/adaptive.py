"""Adaptive concurrency of a served model: the calls kept in flight follow the replicas' latency.

Why: a model the sweep serves itself (``models[].serve``) has no RPM quota; what it can take is
``replicas x max_in_flight`` calls at once - while every replica is up and none is slowed. Past
what the replicas can run, calls wait in Serve's queue (or vLLM's ``num_requests_waiting``): their
latency grows while the throughput does not. A replica that dies mid-run (Serve starts another)
halves what the others can take until it is back. So the gateway's in-flight limit adapts, as
in Netflix's concurrency-limits and Envoy's adaptive concurrency filter: a limit between a
``floor`` and the ``ceiling`` (``replicas x max_in_flight``), AIMD driven by the latency of the
calls against their no-queue baseline and, where the server reports it, its queue length (read
about once a second by :mod:`workers.gateway.queue_feed`).

The rule, per finished call (:meth:`AdaptiveLimit.observe`):

* a call's latency is counted per output token when the reply's size is known: an LLM call's
  time grows with the tokens it generates, so a 250-token reply is not 25 times as slow as a
  10-token one in the sense that matters, while a replica holding more calls than it can batch
  slows every token (vLLM's time per output token) and queues the rest;
* the baseline is the least latency among the last ``baseline_samples`` calls (the no-queue
  round trip: Envoy's minRTT), this one included;
* the call is *congested* when its latency exceeds ``tolerance x baseline``, or the server
  reports requests waiting (``queue > 0``);
* congested: the limit is multiplied by ``backoff`` (never below ``floor``) - at most once per
  round, i.e. only when at least ``slots`` calls finished since the last decrease (TCP's once per
  round trip: the calls admitted under the old limit are still coming back slow);
* not congested: the limit grows by ``1 / limit`` (one slot per round of calls), up to ``ceiling``.

A failed attempt that says the server is short of capacity (:meth:`AdaptiveLimit.failed`: a 5xx -
a lost connection, a replica gone - a timeout, a 429) is a decrease under the same once-per-round rule.
Plain arithmetic on floats, no clock and no I/O: the gateway's admission
(:class:`workers.gateway.limits.AdmissionController`) calls it and applies :attr:`slots`.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

#: failed attempts that say the replicas are short of capacity (not the request's own fault)
CAPACITY_ERRORS = frozenset({"server_error", "timeout", "rate_limit"})


@dataclass(frozen=True)
class LimitChange:
    """The in-flight slots changed (what the gateway records as a ``concurrency_limit`` event)."""

    before: int
    after: int
    #: ``latency``, ``queue``, ``error`` (a decrease) or ``recovered`` (an increase)
    reason: str
    #: the call's latency (per output token when its size was known) and the baseline's
    latency_s: float | None
    baseline_s: float | None
    queue: int | None


@dataclass
class AdaptiveLimit:
    """The in-flight limit of one served model (see the module docstring)."""

    floor: int
    ceiling: int
    tolerance: float = 2.0
    backoff: float = 0.5
    baseline_samples: int = 100
    limit: float = field(init=False)
    #: calls finished since the last decrease (a decrease needs ``slots`` of them)
    since_decrease: int = field(init=False)
    _recent: deque[float] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not 1 <= self.floor <= self.ceiling:
            raise ValueError(f"adaptive concurrency needs 1 <= floor <= ceiling, got floor {self.floor}, ceiling {self.ceiling}")
        if self.tolerance <= 1.0 or not 0.0 < self.backoff < 1.0 or self.baseline_samples < 1:
            raise ValueError("adaptive concurrency needs tolerance > 1, 0 < backoff < 1 and baseline_samples >= 1")
        self.limit = float(self.ceiling)
        self.since_decrease = self.ceiling  # the first congested call may decrease at once
        self._recent = deque(maxlen=self.baseline_samples)

    @property
    def slots(self) -> int:
        """Calls the gateway may keep in flight now."""
        return max(self.floor, min(self.ceiling, math.floor(self.limit)))

    @property
    def baseline_s(self) -> float | None:
        return min(self._recent) if self._recent else None

    def observe(self, latency_s: float, queue: int | None = None, output_tokens: int | None = None) -> LimitChange | None:
        """A call came back after ``latency_s`` (admission to reply) with ``output_tokens`` (when
        known: the latency is then counted per output token); ``queue``: the requests the server
        reports waiting, when it reports them. The change of :attr:`slots`, if any."""
        if output_tokens is not None and output_tokens > 0:
            latency_s = latency_s / output_tokens
        self._recent.append(latency_s)
        baseline = min(self._recent)
        if queue is not None and queue > 0:
            return self._decrease("queue", latency_s, baseline, queue)
        if latency_s > self.tolerance * baseline:
            return self._decrease("latency", latency_s, baseline, queue)
        self.since_decrease += 1
        before = self.slots
        self.limit = min(float(self.ceiling), self.limit + 1.0 / self.limit)
        return self._change(before, "recovered", latency_s, baseline, queue)

    def failed(self, kind: str) -> LimitChange | None:
        """An attempt failed with error ``kind``; a capacity error decreases the limit."""
        if kind not in CAPACITY_ERRORS:
            return None
        return self._decrease("error", None, self.baseline_s, None)

    def _decrease(self, reason: str, latency_s: float | None, baseline: float | None, queue: int | None) -> LimitChange | None:
        before = self.slots
        self.since_decrease += 1
        if self.since_decrease < before:
            return None  # the calls admitted under the old limit are still coming back
        self.since_decrease = 0
        self.limit = max(float(self.floor), self.limit * self.backoff)
        return self._change(before, reason, latency_s, baseline, queue)

    def _change(
        self, before: int, reason: str, latency_s: float | None, baseline: float | None, queue: int | None
    ) -> LimitChange | None:
        after = self.slots
        if after == before:
            return None
        return LimitChange(before, after, reason, latency_s, baseline, queue)
