"""Where a served model's waiting requests are read, per engine (the gateway's queue feed:
:mod:`workers.gateway.queue_feed`; the kinds: :class:`workers.llm.providers.QueueSource`).

Why these ways, with the installed Ray (2.60) and the engines as they are:

* The Serve route cannot give the figure: a ``GET <route>/metrics`` is routed to *one* replica
  (no sum), and waits for a free slot under ``max_ongoing_requests`` like a call - behind the
  very queue it should measure. So the feed talks to the replicas' actors directly (the named
  actors ``SERVE_REPLICA::<app>#<deployment>#<id>`` in namespace ``serve``: Serve's
  ``ReplicaID.to_full_id_str``, ``ray/serve/_private/common.py:89-94``), one actor call per
  replica, outside the router and its slots.
* ``replica_metrics`` (the test double): ``ReplicaActor.record_routing_stats``
  (``ray/serve/_private/replica.py``: the deployment's own ``record_routing_stats``, which Serve's
  controller polls for request routers) returns the replica's engine gauges as Prometheus text,
  summed over the replicas by :func:`workers.gateway.queue_feed.waiting_requests`.
* ``replica_ongoing`` (llama.cpp): llama-cpp-python's server has no metrics route and runs one
  completion at a time under its model lock (``llama_cpp/server/app.py:64-89``,
  abetlen/llama-cpp-python@3691546); ``llamacpp:requests_deferred`` is the C++ ``llama-server``'s
  (with ``--metrics``), which our deployment does not run. Its queue is therefore read from
  Serve's own count: ``ReplicaActor.get_num_ongoing_requests`` (a concurrency group of its own:
  never blocked by user code) less the one request the server runs, summed over the replicas.
* ``ray_metrics`` (vLLM, SGLang under ``ray.serve.llm``): the engine runs inside the ``LLMServer``
  replica, whose ``record_routing_stats`` reports KV-routing endpoints only
  (``ray/llm/_internal/serve/core/server/llm_server.py:603-613``) and whose route has no
  ``/metrics``; its gauges go through ``RayPrometheusStatLogger`` (``log_engine_metrics``, on by
  default: ``ray/llm/_internal/serve/engines/vllm/vllm_engine.py:622-629``; SGLang:
  ``sglang_engine.py:112``) to Ray's metrics agent on each node, which exports them at
  ``http://<node>:<MetricsExportPort>/metrics`` as ``ray_vllm_num_requests_waiting`` /
  ``ray_sglang_num_queue_reqs``. Only where the cluster collects metrics: a local cluster this
  project starts turns collection off (``pipeline.raysetup.SYSTEM_CONFIG``), and Ray's agents
  report every few seconds - there the read finds no sample and the limit keeps its latency
  and error signals.

Replica handles are listed again every :data:`RELIST_S` and after any failed read (a replica
replaced by Serve is a new actor).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Awaitable, Callable
from typing import Any

from workers.gateway.queue_feed import waiting_requests
from workers.llm.providers import QueueSource

#: Serve's namespace and the name prefix of its replica actors (ray/serve/_private/common.py)
SERVE_NAMESPACE = "serve"
REPLICA_PREFIX = "SERVE_REPLICA::"
#: seconds before the replicas' handles are listed again
RELIST_S = 10.0
#: seconds a replica gets to answer a read
REPLICA_TIMEOUT_S = 0.5
#: seconds a node's metrics endpoint gets to answer
SCRAPE_TIMEOUT_S = 2.0


class _Replicas:
    """The actor handles of one Serve application's replicas, listed at most every RELIST_S."""

    def __init__(self, app: str) -> None:
        self.prefix = f"{REPLICA_PREFIX}{app}#"
        self.handles: list[Any] = []
        self.listed_at = -RELIST_S

    def _list(self) -> list[Any]:
        import ray  # lazy: the gateway's process has Ray; tests of the feed do not

        names = [
            a["name"]
            for a in ray.util.list_named_actors(all_namespaces=True)
            if a.get("namespace") == SERVE_NAMESPACE and str(a.get("name", "")).startswith(self.prefix)
        ]
        return [ray.get_actor(n, namespace=SERVE_NAMESPACE) for n in sorted(names)]

    async def get(self) -> list[Any]:
        if time.monotonic() - self.listed_at >= RELIST_S or not self.handles:
            self.handles = await asyncio.to_thread(self._list)  # a GCS call: off the gateway's loop
            self.listed_at = time.monotonic()
        return self.handles

    def forget(self) -> None:
        self.listed_at = -RELIST_S


async def _call(handle: Any, method: str) -> Any:
    return await getattr(handle, method).remote()


async def _per_replica(replicas: _Replicas, method: str) -> list[Any]:
    """``method`` of every replica actor; the replicas that failed or did not answer within
    :data:`REPLICA_TIMEOUT_S` (a killed one that Ray has not declared dead yet) are left out, and
    the handles listed again next time; RuntimeError when none answered."""
    handles = await replicas.get()
    tasks = [asyncio.ensure_future(_call(h, method)) for h in handles]
    done, late = await asyncio.wait(tasks, timeout=REPLICA_TIMEOUT_S) if tasks else (set(), set())
    for t in late:
        t.cancel()
    answered = [t.result() for t in tasks if t in done and not t.cancelled() and t.exception() is None]
    if len(answered) < len(tasks) or not handles:
        replicas.forget()
    if not answered:
        raise RuntimeError(f"no replica of {replicas.prefix} answered {method}")
    return answered


def queue_reader(source: QueueSource) -> Callable[[], Awaitable[int | None]]:
    """The read of ``source``: the waiting requests summed over the replicas (None: no figure)."""
    if source.kind == "ray_metrics":
        return lambda: _ray_metrics(source)
    replicas = _Replicas(source.app)
    if source.kind == "replica_ongoing":

        async def ongoing() -> int | None:
            counts = await _per_replica(replicas, "get_num_ongoing_requests")
            return sum(max(0, int(n) - source.running) for n in counts)

        return ongoing

    async def metrics() -> int | None:
        stats = await _per_replica(replicas, "record_routing_stats")
        figures = [
            waiting_requests(str(s.get("prometheus", "")), source.gauges, source.labels) for s in stats if isinstance(s, dict)
        ]
        known = [f for f in figures if f is not None]
        return sum(known) if known else None

    return metrics


def _metrics_urls() -> list[str]:
    import ray  # lazy: as above

    return [
        f"http://{n['NodeManagerAddress']}:{n['MetricsExportPort']}/metrics"
        for n in ray.nodes()
        if n.get("Alive") and n.get("MetricsExportPort")
    ]


async def _ray_metrics(source: QueueSource) -> int | None:
    import aiohttp  # lazy: the gateway's process has it (litellm's transport)

    urls = await asyncio.to_thread(_metrics_urls)
    total: int | None = None
    timeout = aiohttp.ClientTimeout(total=SCRAPE_TIMEOUT_S)
    async with aiohttp.ClientSession(timeout=timeout) as session:
        for url in urls:
            try:
                async with session.get(url) as resp:
                    text = await resp.text()
            except (aiohttp.ClientError, TimeoutError, OSError):
                continue  # a node restarting: the others still count
            n = waiting_requests(text, source.gauges, source.labels)
            if n is not None:
                total = (total or 0) + n
    return total
