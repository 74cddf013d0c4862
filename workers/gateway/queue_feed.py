"""The queue feed of a served model: the replicas' waiting requests, read about once a second
while calls are in flight, handed to the gateway's adaptive in-flight limit.

Why: a served model's in-flight limit (:mod:`workers.gateway.adaptive`) halves when a call
comes back slow; a queue on the replicas says the same thing sooner and plainly - requests the
engine holds but does not run yet (vLLM's scheduler waiting for KV-cache blocks or a batch slot,
llama.cpp's server behind its model lock). The figure comes from what each engine really
exposes (where, per engine: :class:`workers.llm.providers.QueueSource` and
:mod:`workers.serving.queue_source`); the gauges are read from Prometheus text:

* vLLM: ``vllm:num_requests_waiting`` (labels ``model_name``, ``engine``), defined in
  ``vllm/v1/metrics/loggers.py`` (``PrometheusStatLogger.__init__``, ``gauge_scheduler_waiting``,
  vllm-project/vllm@005a810); exported by Ray's metrics agent as ``ray_vllm_num_requests_waiting``
  (the Serve LLM dashboard's query: ``ray/dashboard/modules/metrics/dashboards/serve_llm_dashboard_panels.py:394``);
* SGLang: ``sglang:num_queue_reqs`` ("the number of requests in the waiting queue",
  ``python/sglang/srt/metrics/collector.py``, sgl-project/sglang@00ae9c1),
  through Ray ``ray_sglang_num_queue_reqs``;
* the test double: vLLM's gauge, in vLLM's exposition format, so the same parser runs in the
  default suite.

The feed (:class:`QueueFeed`) costs nothing per call: one task per deployment gateway that
sleeps ``period_s`` and reads only while calls are in flight. Its figure (the sum over the
replicas) goes to :meth:`workers.gateway.limits.AdmissionController.report_queue`; each call
that finishes while it is fresh observes it (``AdaptiveLimit.observe(queue=...)``), so a queue
halves the limit like a slow reply does, once per round. A read that fails (an engine
restarting, a replica replaced, a metrics endpoint not answering) is counted and ignored: the
limit keeps its latency and error signals, and no call ever waits on a read.
"""

from __future__ import annotations

import asyncio
import logging
import math
import re
from collections.abc import Awaitable, Callable, Iterable, Mapping
from typing import Protocol

log = logging.getLogger(__name__)

#: vLLM's waiting-requests gauge, as its server exposes it and as Ray's metrics agent exports it
VLLM_WAITING = ("vllm:num_requests_waiting", "ray_vllm_num_requests_waiting")
#: SGLang's waiting-queue gauge, likewise
SGLANG_WAITING = ("sglang:num_queue_reqs", "ray_sglang_num_queue_reqs")
#: seconds between two looks at the in-flight count while no call is in flight
IDLE_CHECK_S = 0.1

_NAME = re.compile(r"[a-zA-Z_:][a-zA-Z0-9_:]*")
_LABEL = re.compile(r'\s*([a-zA-Z_][a-zA-Z0-9_]*)\s*=\s*"((?:[^"\\]|\\.)*)"\s*(,)?')
_ESCAPES = {"\\\\": "\\", '\\"': '"', "\\n": "\n"}


def _unescape(value: str) -> str:
    return re.sub(r'\\[\\"n]', lambda m: _ESCAPES[m.group(0)], value)


def samples(text: str) -> Iterable[tuple[str, dict[str, str], float]]:
    """The samples of Prometheus text exposition (``name{label="v",...} value [timestamp]``);
    comments and lines that do not parse are skipped."""
    for raw in text.splitlines():
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        m = _NAME.match(line)
        if m is None:
            continue
        name, pos = m.group(0), m.end()
        labels: dict[str, str] = {}
        if line[pos : pos + 1] == "{":
            pos += 1
            while True:
                lm = _LABEL.match(line, pos)
                if lm is None:
                    break
                labels[lm.group(1)] = _unescape(lm.group(2))
                pos = lm.end()
                if lm.group(3) is None:
                    break
            rest = line[pos:].lstrip()
            if not rest.startswith("}"):
                continue
            pos = len(line) - len(rest) + 1
        parts = line[pos:].split()
        if not parts:
            continue
        try:
            value = float(parts[0])
        except ValueError:
            continue
        yield name, labels, value


def waiting_requests(text: str, gauges: Iterable[str], labels: Mapping[str, str] | None = None) -> int | None:
    """The sum of the samples of ``gauges`` in ``text`` whose labels include ``labels`` (one
    sample per replica, engine or worker: summed); None when ``text`` has no such sample (the
    engine does not report it: not a queue of 0)."""
    names = set(gauges)
    want = dict(labels or {})
    total = 0.0
    found = False
    for name, have, value in samples(text):
        if name not in names or any(have.get(k) != v for k, v in want.items()) or math.isnan(value):
            continue
        found = True
        total += value
    return round(total) if found else None


class QueueTarget(Protocol):
    """What the feed feeds (an :class:`workers.gateway.limits.AdmissionController`)."""

    active: int

    def report_queue(self, queue: int, fresh_s: float) -> None: ...


class QueueFeed:
    """Reads a served model's waiting requests every ``period_s`` while calls are in flight and
    reports them to ``target`` (see the module docstring). ``read``: the figure summed over the
    replicas, None when the engine reports none; an exception is a failed read."""

    def __init__(self, target: QueueTarget, read: Callable[[], Awaitable[int | None]], period_s: float = 1.0) -> None:
        self.target = target
        self.read = read
        self.period_s = period_s
        self.reads = 0
        self.failures = 0
        self.last: int | None = None

    async def poll_once(self) -> int | None:
        """One read (at most ``2 x period_s``), reported when it gave a figure; None otherwise."""
        self.reads += 1
        try:
            queue = await asyncio.wait_for(self.read(), timeout=2 * self.period_s)
        except asyncio.CancelledError:
            raise
        except Exception as exc:  # an engine restarting, a replica replaced: the limit keeps its other signals
            self.failures += 1
            log.debug("queue read failed: %s", exc)
            return None
        if queue is None:
            return None
        self.last = queue
        # fresh for two periods: a call finishing after the next read missed still sees it
        self.target.report_queue(queue, fresh_s=2 * self.period_s)
        return queue

    async def run(self) -> None:
        """Until cancelled: a read each ``period_s`` while the target has calls in flight (the
        first within :data:`IDLE_CHECK_S` of the first call: a look at a counter, no read)."""
        while True:
            if self.target.active > 0:
                await self.poll_once()
                await asyncio.sleep(self.period_s)
            else:
                await asyncio.sleep(min(self.period_s, IDLE_CHECK_S))
