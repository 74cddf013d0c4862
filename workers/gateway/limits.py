"""Admission control of one deployment: RPM/TPM windows, adaptive concurrency, Retry-After.

Why sliding windows rather than refilling token buckets: providers count requests and tokens
per minute, and a bucket that starts full lets through up to twice its limit in one minute
(a full burst, then the refill). Here every request takes an entry in a request window and a
token window; a request is admitted only when the entries within ``window_s + pad_s`` leave
room for it. An entry counts from admission until a window's length after its response came
back (the provider saw the request somewhere in between), so no provider-side window can see
more than the limit whatever the client's or the network's delays. A token entry is sized
before the call (counted prompt + max output) and corrected to the reported usage after it.

Concurrency is AIMD: halve the in-flight limit on HTTP 429 (at most once per Retry-After
pause) and add 1/limit per success, back up to ``max_concurrency``. A 429's Retry-After
pauses every new attempt of the deployment. 5xx and timeouts retry without shrinking.
A served model (``DeploymentConfig.min_concurrency`` set) adapts its in-flight limit instead to the
replicas' latency and capacity errors, between that floor and ``max_concurrency``
(:mod:`workers.gateway.adaptive`). Admission is FIFO: one waiter at a time holds the window lock, so large requests do not starve.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from workers.gateway.adaptive import AdaptiveLimit, LimitChange


class AdmissionError(ValueError):
    """A request that can never be admitted (bigger than the token window)."""


class _Entry:
    __slots__ = ("t", "amount", "ends", "held")

    def __init__(self, t: float, amount: int, ends: float | None):
        self.t = t
        self.amount = amount
        #: the time the entry's window starts to run out; None while the request is in flight
        self.ends = ends
        #: still among its window's entries (not pruned or removed): its amount is in the total
        self.held = True


class SlidingWindow:
    """Amounts sent within the last ``span_s`` seconds; room for ``amount`` when sum + amount <= limit.

    With ``anchor="response"`` (default) an entry counts from its admission until ``span_s``
    after its *response* arrived: the provider saw the request somewhere in between, so the
    entry covers every provider-side window that can contain it, whatever the delays of the
    client or the network. With ``anchor="admission"`` it counts for ``span_s`` from admission
    (higher utilisation for slow generations; ``pad_s`` must then cover the send delay).

    Why two collections: a window holds every request of the last ``span_s`` (thousands at a
    high RPM), and every admission asks it for room. Entries still in flight sit in a set; an
    entry whose window started to run out moves to a queue kept in order of that time (responses
    arrive in clock order), so pruning pops from its front and never scans the window, and
    ``finish`` is O(1) (issue 37: the scans were a window's length of steps per call).
    """

    def __init__(self, limit: int | None, span_s: float, anchor: str = "response"):
        if anchor not in ("response", "admission"):
            raise ValueError(f"window anchor must be 'response' or 'admission', got {anchor!r}")
        self.limit = limit
        self.span_s = span_s
        self.anchor = anchor
        #: entries in flight (no ``ends`` yet)
        self._flight: set[_Entry] = set()
        #: entries whose window runs out, in order of ``ends``
        self._ending: deque[_Entry] = deque()
        self.total = 0

    @property
    def _entries(self) -> list[_Entry]:
        """Every entry the window holds (in flight first, then by the end of their window)."""
        return [*self._flight, *self._ending]

    def _queue(self, entry: _Entry) -> None:
        """Put an entry whose ``ends`` is set in the queue, keeping it ordered by ``ends``."""
        ending = self._ending
        if not ending or ending[-1].ends <= entry.ends:  # type: ignore[operator]  # queued entries have ends
            ending.append(entry)
            return
        i = len(ending)  # a clock that went back (a test's): insert in order
        while i > 0 and ending[i - 1].ends > entry.ends:  # type: ignore[operator]
            i -= 1
        ending.insert(i, entry)

    def _prune(self, now: float) -> None:
        cutoff = now - self.span_s
        ending = self._ending
        while ending and ending[0].ends <= cutoff:  # type: ignore[operator]
            e = ending.popleft()
            e.held = False
            self.total -= e.amount

    def wait_s(self, amount: int, now: float) -> float:
        """Seconds until ``amount`` fits (0 when it fits now; ``span_s`` when only requests
        still in flight could make room - a finishing request wakes the waiter earlier)."""
        if self.limit is None:
            return 0.0
        self._prune(now)
        if self.total + amount <= self.limit:
            return 0.0
        remaining = self.total
        for e in self._ending:  # in order of the end of their window
            remaining -= e.amount
            if remaining + amount <= self.limit:
                return max(1e-4, e.ends + self.span_s - now)  # type: ignore[operator]
        return self.span_s

    def add(self, amount: int, now: float) -> _Entry:
        e = _Entry(now, amount, now if self.anchor == "admission" else None)
        if e.ends is None:
            self._flight.add(e)
        else:
            self._queue(e)
        self.total += amount
        if self.limit is None:  # nothing asks an unlimited window for room: it prunes itself
            self._prune(now)
        return e

    def finish(self, entry: _Entry, now: float, amount: int | None = None) -> None:
        """The request's response arrived (its window starts to run out); ``amount`` replaces
        the estimate by the actual usage."""
        if entry.ends is None:
            entry.ends = now
            if entry.held:
                self._flight.discard(entry)
                self._queue(entry)
        if amount is not None:
            if entry.held:
                self.total += amount - entry.amount
            entry.amount = amount

    def remove(self, entry: _Entry) -> None:
        if not entry.held:
            return
        if entry in self._flight:
            self._flight.discard(entry)
        else:
            for i, e in enumerate(self._ending):
                if e is entry:
                    del self._ending[i]
                    break
            else:
                return
        entry.held = False
        self.total -= entry.amount

    def usage(self, now: float) -> tuple[int, int]:
        self._prune(now)
        return len(self._flight) + len(self._ending), self.total


@dataclass
class Ticket:
    """An admitted attempt: its window entries, released with the outcome."""

    request_entry: _Entry
    token_entry: _Entry
    admitted_at: float
    released: bool = False


class AdmissionController:
    """Decides when one deployment's next attempt may go out: the RPM/TPM sliding windows, the AIMD
    in-flight limit and Retry-After pauses (see the module docstring). ``acquire`` waits for room;
    ``release`` or ``cancel`` gives it back."""

    def __init__(
        self,
        *,
        rpm: int | None,
        tpm: int | None,
        window_s: float,
        pad_s: float,
        max_concurrency: int,
        rate_limit_default_wait_s: float = 5.0,
        anchor: str = "response",
        clock: Callable[[], float] = time.monotonic,
        adaptive: AdaptiveLimit | None = None,
        on_limit: Callable[[LimitChange], None] | None = None,
    ):
        self._clock = clock
        #: a served model's latency-driven limit (workers.gateway.adaptive); None: AIMD on 429 only
        self.adaptive = adaptive
        self.on_limit = on_limit
        self.requests = SlidingWindow(rpm, window_s + pad_s, anchor)
        self.tokens = SlidingWindow(tpm, window_s + pad_s, anchor)
        self.max_concurrency = max_concurrency
        self.limit = float(max_concurrency)
        self.active = 0
        self.rate_limit_default_wait_s = rate_limit_default_wait_s
        self.paused_until = 0.0
        self.paused = False
        self._waiters: deque[asyncio.Future] = deque()
        self._window_lock = asyncio.Lock()
        self._window_changed = asyncio.Event()
        self.rate_limited = 0
        self.shrinks = 0
        #: a served model's waiting requests as last read (workers.gateway.queue_feed) and until when it holds
        self.queue: int | None = None
        self.queue_until = 0.0

    # ---- admission ----
    def _slots(self) -> int:
        return max(1, math.floor(self.limit))

    def _wake(self) -> None:
        while self._waiters:
            fut = self._waiters.popleft()
            if not fut.done():
                fut.set_result(None)

    async def _enter(self) -> None:
        while self.paused or self.active >= self._slots():
            fut = asyncio.get_running_loop().create_future()
            self._waiters.append(fut)
            try:
                await fut
            except asyncio.CancelledError:
                if fut in self._waiters:
                    self._waiters.remove(fut)
                raise
        self.active += 1

    async def _sleep_interruptibly(self, seconds: float) -> None:
        """Sleep, but wake early when limits change (set_limits, resume)."""
        self._window_changed.clear()
        try:
            await asyncio.wait_for(self._window_changed.wait(), timeout=seconds)
        except TimeoutError:
            pass

    def _check_size(self, tokens: int) -> None:
        """A request bigger than the token window can never be admitted."""
        if self.tokens.limit is not None and tokens > self.tokens.limit:
            raise AdmissionError(
                f"request needs {tokens} tokens (prompt + max output), more than the deployment's TPM limit {self.tokens.limit}"
            )

    async def acquire(self, tokens: int) -> Ticket:
        """Wait for a concurrency slot, the end of any Retry-After pause and window room."""
        self._check_size(tokens)
        await self._enter()
        try:
            async with self._window_lock:
                while True:
                    now = self._clock()
                    wait = max(self.requests.wait_s(1, now), self.tokens.wait_s(tokens, now), self.paused_until - now)
                    if wait <= 0 and not self.paused:
                        break
                    await self._sleep_interruptibly(wait if wait > 0 else 0.05)
                return Ticket(self.requests.add(1, now), self.tokens.add(tokens, now), now)
        except BaseException:
            self.active -= 1
            self._wake()
            raise

    def release(
        self,
        ticket: Ticket,
        outcome: str,
        *,
        actual_tokens: int | None = None,
        retry_after_s: float | None = None,
        pause: bool = True,
        output_tokens: int | None = None,
    ) -> None:
        """``outcome``: ``ok`` or an error kind. Corrects the token entry on success.

        A ``rate_limit`` outcome pauses every new attempt for ``retry_after_s`` (or the default
        wait) unless ``pause`` is False (a Retry-After beyond the deployment's cap: that call
        fails instead, and the others are not held for it)."""
        if ticket.released:
            return
        ticket.released = True
        self.active -= 1
        now = self._clock()
        self.requests.finish(ticket.request_entry, now)
        self.tokens.finish(ticket.token_entry, now, actual_tokens if outcome == "ok" else None)
        if outcome == "ok" and self.adaptive is None:
            self.limit = min(float(self.max_concurrency), self.limit + 1.0 / self.limit)
        elif outcome == "rate_limit":
            self.rate_limited += 1
            if now >= self.paused_until:  # one shrink per pause: a burst of 429s halves once
                self.limit = max(1.0, self.limit / 2.0)
                self.shrinks += 1
            if pause:
                wait = self.rate_limit_default_wait_s if retry_after_s is None else retry_after_s
                self.paused_until = max(self.paused_until, now + wait)
        if self.adaptive is not None and outcome != "cancelled":
            self._adapt(outcome, now - ticket.admitted_at, output_tokens)
        self._window_changed.set()  # a finished request may make room in the windows
        self._wake()

    def cancel(self, ticket: Ticket) -> None:
        """Return an admission that sent nothing: its window entries are removed."""
        if ticket.released:
            return
        ticket.released = True
        self.active -= 1
        self.requests.remove(ticket.request_entry)
        self.tokens.remove(ticket.token_entry)
        self._window_changed.set()
        self._wake()

    def report_queue(self, queue: int, fresh_s: float) -> None:
        """The replicas of a served model hold ``queue`` requests waiting (read by the queue feed:
        workers.gateway.queue_feed); each call that finishes within ``fresh_s`` observes it."""
        self.queue = queue
        self.queue_until = self._clock() + fresh_s

    def _adapt(self, outcome: str, latency_s: float, output_tokens: int | None) -> None:
        """A served model's limit follows its latency, its replicas' queue (when the queue feed
        reads one) and capacity errors (workers.gateway.adaptive)."""
        assert self.adaptive is not None
        ok = outcome == "ok"
        queue = self.queue if self.queue is not None and self._clock() <= self.queue_until else None
        change = (
            self.adaptive.observe(latency_s, queue=queue, output_tokens=output_tokens) if ok else self.adaptive.failed(outcome)
        )
        self.limit = float(self.adaptive.slots)
        if change is not None and self.on_limit is not None:
            self.on_limit(change)

    # ---- control ----
    def pause(self) -> None:
        self.paused = True

    def resume(self) -> None:
        self.paused = False
        self._window_changed.set()
        self._wake()

    def set_limits(self, *, rpm: int | None = None, tpm: int | None = None, max_concurrency: int | None = None) -> None:
        if rpm is not None:
            self.requests.limit = rpm
        if tpm is not None:
            self.tokens.limit = tpm
        if max_concurrency is not None:
            self.max_concurrency = max_concurrency
            self.limit = float(max_concurrency)
            if self.adaptive is not None:  # the new ceiling, from where the limit adapts again
                self.adaptive.ceiling = max_concurrency
                self.adaptive.floor = min(self.adaptive.floor, max_concurrency)
                self.adaptive.limit = self.limit
        self._window_changed.set()
        self._wake()

    def stats(self) -> dict:
        """Figures for the progress line. ``window_requests`` / ``window_tokens``: what the
        request and token windows hold now (per ``window_s + pad_s``); ``paused_until``: epoch
        seconds until which a provider's Retry-After holds new attempts (None when not paused)."""
        now = self._clock()
        n_req, _ = self.requests.usage(now)
        _, n_tok = self.tokens.usage(now)
        pause_left = max(0.0, self.paused_until - now)
        return {
            "active": self.active,
            "waiting": len(self._waiters),
            "concurrency_limit": self.limit,
            "max_concurrency": self.max_concurrency,
            "paused": self.paused,
            "retry_after_pause_s": pause_left,
            "paused_until": time.time() + pause_left if pause_left > 0 else None,
            "window_requests": n_req,
            "window_tokens": n_tok,
            "rpm": self.requests.limit,
            "tpm": self.tokens.limit,
            "rate_limited": self.rate_limited,
            "shrinks": self.shrinks,
        }
