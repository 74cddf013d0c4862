"""What a served model will cost before the run: its output tokens over its measured tokens/s.

Why tokens/s: a served model is paid by the hour its replicas are held (``prices: {gpu_hour: X}``
or ``{replica_hour: X}``), not by the token, so ``recap estimate`` needs how fast the replicas
turn tokens out. Two sources, named wherever the figure is shown:

* ``serve.tokens_per_s`` in the sweep (output tokens per second of one replica holding its
  ``max_in_flight`` calls: a figure from an earlier run or a benchmark) - ``from the sweep``;
* ``recap estimate --probe`` (:func:`probe`): the model deployed as a run would deploy it, one wave
  of ``replicas x max_in_flight`` requests sent :data:`PROBE_WAVES` times, the output tokens the
  server reports over the wall time of the waves, divided by the replicas; taken down at
  once - ``measured by probe``.

The arithmetic (:func:`serving_cost`): the run holds the replicas for ``output tokens /
(tokens_per_s x replicas x efficiency)`` seconds, each replica-hour at its price, where the
efficiency is the share of the replicas' slots the episode workers can fill (each worker has
one call in flight: ``min(1, workers / (replicas x max_in_flight))``). Prompt tokens are left
out: prefill is a small part of a call's time, and prefix caching makes ReCAP's re-sent
prefixes cheaper still. The time to load the weights is not counted either (the run's
``serve_started`` event says what it was).
"""

from __future__ import annotations

import json
import time
import urllib.request
import uuid
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

from pipeline.serving.engines import ServePlan
from pipeline.spec import SweepSpec

FROM_SWEEP = "from the sweep"
MEASURED = "measured by probe"
#: waves of ``replicas x max_in_flight`` requests a probe sends (the first also warms the replicas up)
PROBE_WAVES = 2
#: output tokens a probe request asks for at most
PROBE_MAX_TOKENS = 128
PROBE_PROMPT = "Describe, step by step, how to make a cup of tea in a small kitchen."
#: seconds a probe request may take
PROBE_TIMEOUT_S = 300.0


@dataclass(frozen=True)
class Throughput:
    """Output tokens per second of one replica, and where the figure comes from."""

    tokens_per_s: float
    source: str


@dataclass(frozen=True)
class ServingCost:
    """The estimate of one served model: seconds the replicas are held, replica-hours, dollars."""

    held_s: float
    replica_hours: float
    usd: float


def efficiency(plan: ServePlan, workers: int) -> float:
    """The share of the replicas' slots the sweep's episode workers can keep busy."""
    return min(1.0, workers / plan.concurrency)


def serving_cost(output_tokens: float, plan: ServePlan, tokens_per_s: float, workers: int) -> ServingCost:
    """What serving ``output_tokens`` costs (see the module docstring)."""
    held_s = output_tokens / (tokens_per_s * plan.replicas * efficiency(plan, workers))
    replica_hours = plan.replicas * held_s / 3600.0
    return ServingCost(held_s, replica_hours, replica_hours * plan.usd_per_replica_hour)


def sweep_throughput(spec: SweepSpec) -> dict[str, Throughput]:
    """The served models whose sweep entry gives ``serve.tokens_per_s``."""
    return {
        m.name: Throughput(m.serve.tokens_per_s, FROM_SWEEP)
        for m in spec.models
        if m.serve is not None and m.serve.tokens_per_s is not None
    }


def _ask(api_base: str, model: str) -> int:
    """One probe request; the output tokens the server reports."""
    body = {
        "model": model,
        "messages": [{"role": "user", "content": PROBE_PROMPT}],
        "max_tokens": PROBE_MAX_TOKENS,
        "temperature": 0.0,
    }
    req = urllib.request.Request(
        api_base.rstrip("/") + "/chat/completions",
        data=json.dumps(body).encode(),
        headers={"content-type": "application/json"},
        method="POST",
    )
    with urllib.request.urlopen(req, timeout=PROBE_TIMEOUT_S) as resp:
        return int(json.loads(resp.read())["usage"]["completion_tokens"])


def measure(api_base: str, plan: ServePlan, waves: int = PROBE_WAVES) -> float:
    """Output tokens per second of one replica of the model served at ``api_base``."""
    n = plan.concurrency
    with ThreadPoolExecutor(max_workers=n) as pool:
        t0 = time.monotonic()
        tokens = 0
        for _ in range(waves):
            tokens += sum(pool.map(lambda _: _ask(api_base, plan.served_name), range(n)))
        wall = time.monotonic() - t0
    return tokens / wall / plan.replicas


def probe(spec: SweepSpec, labels: list[str] | None = None) -> dict[str, Throughput]:
    """Deploy the served models named (all of them by default) on the connected Ray cluster as a run
    would, measure each one's tokens/s (:func:`measure`) and take them down again."""
    from pipeline.serving.service import ServedModels  # lazy: the service loads Serve when it starts

    wanted = [m for m in spec.models if m.serve is not None and (labels is None or m.name in labels)]
    if not wanted:
        return {}
    sub = spec.model_copy(update={"models": wanted})
    served = ServedModels(sub, f"probe-{uuid.uuid4().hex[:8]}", lambda *a, **k: None)
    try:
        served.start()
        return {label: Throughput(measure(s.api_base, s.plan), MEASURED) for label, s in served.served.items()}
    finally:
        served.close()
