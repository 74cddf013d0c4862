"""The run's Wikipedia politeness on Ray: one actor holding a token bucket per host, asked by every worker.

Why an actor: each episode worker is its own process, so a bucket per process lets ``workers: 8``
send eight times the rate. The driver starts one named :class:`WikiPoliteness` per run that has a
FEVER environment (pipeline/run_services.py, from FeverBenchmark.run_services) and names it to the episode workers
(:data:`~workers.envs.fever.ratelimit.POLITENESS_VAR`); their environments reach it through
:class:`RemoteLimiter`. Reservation semantics: the actor only books a slot and answers how long
to wait, the caller sleeps in its own process, so the actor never blocks and answers in
microseconds. A restarted actor (``max_restarts=-1``, as the gateway's) starts with full buckets:
at most one extra burst per host.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import ray

from workers.envs.fever.ratelimit import TokenBucket
from workers.envs.fever.wiki import WikiError

#: how long an environment waits for the actor's answer before the request counts as unavailable
RESERVE_TIMEOUT_S = 60.0


@ray.remote(num_cpus=0)
class WikiPoliteness:
    """One token bucket per host for the whole run; the politest rate and burst any caller asks for win."""

    def __init__(self) -> None:
        self._buckets: dict[str, TokenBucket] = {}
        self._reservations: dict[str, int] = {}

    async def reserve(self, host: str, rate: float, burst: int) -> float:
        """Book the next request to ``host``; the seconds the caller waits before sending it."""
        bucket = self._buckets.get(host)
        if bucket is None:
            bucket = self._buckets[host] = TokenBucket(rate, burst)
        else:  # two environment entries asking different rates of one host: the lower holds
            bucket.rate, bucket.burst = min(bucket.rate, float(rate)), min(bucket.burst, int(burst))
        self._reservations[host] = self._reservations.get(host, 0) + 1
        return bucket.reserve(host)

    async def stats(self) -> dict[str, dict[str, float]]:
        """Per host: the rate and burst in force and the requests booked so far (by this incarnation)."""
        return {
            host: {"rate": b.rate, "burst": float(b.burst), "reservations": float(self._reservations[host])}
            for host, b in self._buckets.items()
        }


_handles: dict[str, Any] = {}
_handles_lock = threading.Lock()


def _handle(name: str) -> Any:
    """The named actor's handle, looked up once per process (a restart keeps the same handle valid)."""
    with _handles_lock:
        if name not in _handles:
            _handles[name] = ray.get_actor(name)  # the job's namespace: the driver created it in this job
        return _handles[name]


class RemoteLimiter:
    """A :class:`~workers.envs.fever.ratelimit.RateLimiter` that books each request with the run's
    :class:`WikiPoliteness` actor, then sleeps here; an actor that cannot be reached makes the
    request unavailable (WikiError: the episode ends ``wiki_error``), never an unlimited one."""

    def __init__(self, name: str, rate: float, burst: int, *, sleep: Callable[[float], None] = time.sleep) -> None:
        self.name = name
        self.rate = float(rate)
        self.burst = int(burst)
        self._sleep = sleep

    def acquire(self, host: str) -> None:
        """Wait until the run's limit allows one more request to ``host``."""
        try:
            wait = ray.get(_handle(self.name).reserve.remote(host, self.rate, self.burst), timeout=RESERVE_TIMEOUT_S)
        except (ValueError, ray.exceptions.RayError) as exc:  # ValueError: no actor of that name
            raise WikiError(
                "unavailable", f"the run's Wikipedia rate limiter {self.name!r} cannot be reached ({type(exc).__name__})"
            ) from None
        if wait > 0:
            self._sleep(wait)
