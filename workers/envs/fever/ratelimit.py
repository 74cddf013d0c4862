"""Per-host politeness for Wikipedia requests: the rate limit every FEVER environment of a run shares.

Why an interface: the limit must hold across all workers of a run (Wikipedia asks clients to stay
gentle), which on a cluster means one limiter that every worker asks: the run's
:class:`~workers.envs.fever.politeness.WikiPoliteness` Ray actor. The environments only call
:meth:`RateLimiter.acquire`; :class:`TokenBucket` is the process-local implementation (and what the
actor runs inside itself); ``benchmark.run_limiter`` picks the run's actor when the episode worker
names one (:data:`POLITENESS_VAR`), else the process's one bucket (:func:`shared_limiter`: ``recap
env play``, tests, the in-process executor, where the process is the whole run).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from typing import Any, Protocol

#: requests per second per host when nothing else is said: well under Wikipedia's published
#: guidance for unauthenticated clients, so a sweep of many workers stays polite
DEFAULT_RATE = 2.0
DEFAULT_BURST = 2
#: the most the ``wikipedia_rate`` option accepts, requests per second per host for the whole run
MAX_RATE = 10.0
#: the environment variable naming the run's WikiPoliteness actor; the driver sets it on the
#: episode workers of a run with a FEVER environment (pipeline/run_services.py)
POLITENESS_VAR = "RECAP_WIKI_POLITENESS"


def check_rate(value: Any) -> float:
    """``value`` as a rate in requests per second per host, in (0, :data:`MAX_RATE`]; else ValueError naming the option."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) or not 0 < value <= MAX_RATE:
        raise ValueError(
            f"wikipedia_rate must be a number of requests per second per host above 0 and at most {MAX_RATE:g}, got {value!r}"
        )
    return float(value)


class RateLimiter(Protocol):
    """Something that makes a caller wait until it may send one more request to ``host``."""

    def acquire(self, host: str) -> None:
        """Block until one request to ``host`` is allowed."""
        ...


class TokenBucket:
    """A token bucket per host: ``rate`` requests per second on average, up to ``burst`` at once.

    Thread-safe; ``clock`` and ``sleep`` are injectable so tests can run it without waiting."""

    def __init__(
        self,
        rate: float = DEFAULT_RATE,
        burst: int = DEFAULT_BURST,
        *,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        if not rate > 0:
            raise ValueError(f"rate must be > 0 requests per second, got {rate!r}")
        if burst < 1:
            raise ValueError(f"burst must be >= 1, got {burst!r}")
        self.rate = float(rate)
        self.burst = int(burst)
        self._clock = clock
        self._sleep = sleep
        self._lock = threading.Lock()
        self._tokens: dict[str, float] = {}
        self._stamp: dict[str, float] = {}

    def reserve(self, host: str) -> float:
        """Take a token for ``host`` now (the balance may go negative); the seconds to wait before using it."""
        with self._lock:
            now = self._clock()
            tokens = self._tokens.get(host, float(self.burst))
            tokens = min(float(self.burst), tokens + (now - self._stamp.get(host, now)) * self.rate)
            tokens -= 1.0
            self._tokens[host], self._stamp[host] = tokens, now
            return 0.0 if tokens >= 0 else -tokens / self.rate

    def acquire(self, host: str) -> None:
        """Wait until a request to ``host`` fits the rate (reservations keep callers in arrival order)."""
        wait = self.reserve(host)
        if wait > 0:
            self._sleep(wait)


_shared_lock = threading.Lock()
_SHARED: dict[tuple[float, int], TokenBucket] = {}


def shared_limiter(rate: float = DEFAULT_RATE, burst: int = DEFAULT_BURST) -> TokenBucket:
    """The process's one bucket for these settings, so every environment of a worker shares it."""
    key = (float(rate), int(burst))
    with _shared_lock:
        bucket = _SHARED.get(key)
        if bucket is None:
            bucket = _SHARED[key] = TokenBucket(rate, burst)
        return bucket
