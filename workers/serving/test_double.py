"""TEST DOUBLE engine (``serve: {engine: test-double}``): a Ray Serve deployment answering OpenAI
chat completions the way the ``offline/`` test doubles answer.

Why: a served model's whole path - deployed by the sweep, replicas placed by Serve, the gateway
calling the route over HTTP, a replica killed mid-run and replaced, the replica-hours charged -
must be tested without weights or a GPU. The answer itself is the in-process test double's
(:func:`workers.llm.offline.provider.offline_reply`): the offline provider forwards the call's
hints in the request body (:mod:`workers.llm.offline.remote`) and this deployment answers with
the same text, tool calls and estimated usage, so ReAct and ReCAP episodes succeed on it. The
model string stays ``offline/expert`` (or ``offline/random``), so every record and the CLI
label it a test double.

``engine_args``: ``latency_s`` (seconds each answer waits, so that calls are in flight when a
test kills a replica) and ``max_running`` (the answers a replica works on at once, as vLLM's
scheduler runs at most a batch; the other requests wait their turn - a queue; 0, the default:
no limit). Nothing else is accepted (:data:`ENGINE_ARGS`).

Its queue, as vLLM reports it: each replica answers Serve's ``record_routing_stats`` with its
gauges in vLLM's Prometheus exposition (:func:`metrics_text`: ``vllm:num_requests_waiting`` and
``vllm:num_requests_running``, labels ``engine`` and ``model_name``), which the gateway's queue
feed reads from every replica and sums (:mod:`workers.serving.queue_source`,
:mod:`workers.gateway.queue_feed`).

Prefix caching, as vLLM's automatic prefix caching reports it: each replica remembers the
message prefixes it has seen (:class:`PrefixCache`, per replica like vLLM's KV cache), and an
answer reports the prompt tokens of the longest one the request repeats as
``usage.prompt_tokens_details.cached_tokens`` (message-granular where vLLM is block-granular),
so a test can assert the cache columns of ``llm_calls`` exactly.
"""

from __future__ import annotations

import asyncio
import hashlib
import json
import os
import time
import uuid
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from typing import Any

from workers.llm.offline.provider import offline_reply
from workers.llm.offline.wire import OFFLINE_METADATA_KEY
from workers.llm.tokens import REPLY_PRIMING_TOKENS, estimate_prompt_tokens, estimate_text_tokens

#: the engine arguments the test double takes
ENGINE_ARGS = ("latency_s", "max_running")
#: what a replica answers on ``GET <route>/health``
HEALTHY = {"status": "ok"}
#: message prefixes a replica remembers (the least recently used leave first)
PREFIX_CACHE_SIZE = 4096


class PrefixCache:
    """The message prefixes one replica has seen; :meth:`cached_tokens` of a request is the prompt
    tokens of the longest prefix of its messages seen before (each message's chars/4 + 3, the
    usage estimate's own count), and remembers every prefix of the request."""

    def __init__(self, size: int = PREFIX_CACHE_SIZE) -> None:
        self.size = size
        self._seen: OrderedDict[str, None] = OrderedDict()

    def cached_tokens(self, messages: Sequence[Mapping[str, Any]]) -> int:
        digest = hashlib.sha256()
        cached = 0
        missed = False
        for i, m in enumerate(messages):
            digest.update(json.dumps([m.get("role"), m.get("content")]).encode())
            key = digest.hexdigest()
            if not missed and key in self._seen:
                cached = estimate_prompt_tokens(messages[: i + 1]) - REPLY_PRIMING_TOKENS
                self._seen.move_to_end(key)
            else:
                missed = True
                self._seen[key] = None
        while len(self._seen) > self.size:
            self._seen.popitem(last=False)
        return cached


def chat_answer(body: Mapping[str, Any], cache: PrefixCache | None = None) -> dict[str, Any]:
    """The OpenAI chat-completion answer to one request body (the test double's reply, its
    tool calls and the chars/4 usage estimate the in-process provider reports; with ``cache``,
    the prompt tokens of the prefix it has seen as ``prompt_tokens_details.cached_tokens``)."""
    model = str(body.get("model") or "expert").removeprefix("offline/")
    messages = [{"role": str(m.get("role")), "content": str(m.get("content") or "")} for m in body.get("messages") or []]
    tools = tuple(
        str(t["function"]["name"])
        for t in body.get("tools") or ()
        if isinstance(t, Mapping) and isinstance(t.get("function"), Mapping)
    )
    stop = body.get("stop")
    stops = () if stop is None else ((stop,) if isinstance(stop, str) else tuple(str(s) for s in stop))
    metadata = {OFFLINE_METADATA_KEY: body.get(OFFLINE_METADATA_KEY) or {}}
    answer = offline_reply(model, messages, metadata, None, tools, stops)
    message: dict[str, Any] = {"role": "assistant", "content": answer.text}
    finish = "stop"
    if answer.tool_calls:
        message["tool_calls"] = [
            {"id": c["id"], "type": "function", "function": {"name": c["name"], "arguments": c["arguments"]}}
            for c in answer.tool_calls
        ]
        finish = "tool_calls"
    prompt = estimate_prompt_tokens(messages)
    completion = estimate_text_tokens(answer.text + "".join(c["name"] + c["arguments"] for c in answer.tool_calls))
    usage: dict[str, Any] = {"prompt_tokens": prompt, "completion_tokens": completion, "total_tokens": prompt + completion}
    if cache is not None:
        usage["prompt_tokens_details"] = {"cached_tokens": cache.cached_tokens(messages)}
    return {
        "id": f"chatcmpl-{uuid.uuid4().hex[:12]}",
        "object": "chat.completion",
        "created": int(time.time()),
        "model": f"offline/{model}",
        "choices": [{"index": 0, "message": message, "finish_reason": finish}],
        "usage": usage,
        # which replica answered (tests check the calls were spread, and which one to kill)
        "system_fingerprint": f"replica-{os.getpid()}",
    }


def metrics_text(model: str, waiting: int, running: int) -> str:
    """A replica's gauges as vLLM's server exposes them on ``/metrics`` (names, help, labels:
    ``vllm/v1/metrics/loggers.py``, ``PrometheusStatLogger``; values as prometheus_client prints
    them)."""
    labels = f'engine="0",model_name="{model}"'
    return (
        "# HELP vllm:num_requests_running Number of requests in model execution batches.\n"
        "# TYPE vllm:num_requests_running gauge\n"
        f"vllm:num_requests_running{{{labels}}} {float(running)}\n"
        "# HELP vllm:num_requests_waiting Number of requests waiting to be processed.\n"
        "# TYPE vllm:num_requests_waiting gauge\n"
        f"vllm:num_requests_waiting{{{labels}}} {float(waiting)}\n"
    )


class TestDoubleServer:
    """The deployment's class (wrapped by ``serve.deployment`` in :func:`deployment`): routes
    ``POST .../v1/chat/completions``, ``GET .../v1/models`` and ``GET .../health``."""

    __test__ = False  # not a pytest class

    def __init__(self, model: str, engine_args: Mapping[str, Any] | None = None) -> None:
        self.model = model
        self.latency_s = float((engine_args or {}).get("latency_s", 0.0))
        max_running = int((engine_args or {}).get("max_running", 0))
        #: the answers worked on at once (None: no limit) and the requests waiting for one
        self.slots = asyncio.Semaphore(max_running) if max_running > 0 else None
        self.waiting = 0
        self.running = 0
        self.prefixes = PrefixCache()

    async def __call__(self, request: Any) -> Any:
        from starlette.responses import JSONResponse  # lazy: Serve's web stack loads in the replica

        path = request.url.path.rstrip("/")
        if request.method == "GET" and path.endswith("/health"):
            return JSONResponse(HEALTHY)
        if request.method == "GET" and path.endswith("/v1/models"):
            return JSONResponse({"object": "list", "data": [{"id": self.model, "object": "model"}]})
        if request.method != "POST" or not path.endswith("/chat/completions"):
            return JSONResponse({"error": {"message": f"no route {request.method} {path}", "type": "not_found"}}, status_code=404)
        try:
            body = await request.json()
        except ValueError:
            return JSONResponse({"error": {"message": "the body is not JSON", "type": "invalid_request_error"}}, status_code=400)
        if self.slots is None:
            return await self._answer(body)
        self.waiting += 1
        try:
            await self.slots.acquire()
        finally:
            self.waiting -= 1
        try:
            return await self._answer(body)
        finally:
            self.slots.release()

    async def _answer(self, body: Any) -> Any:
        from starlette.responses import JSONResponse  # lazy: as above

        self.running += 1
        try:
            if self.latency_s:
                await asyncio.sleep(self.latency_s)
            return JSONResponse(chat_answer(body, self.prefixes))
        except ValueError as exc:
            return JSONResponse({"error": {"message": str(exc), "type": "invalid_request_error"}}, status_code=400)
        finally:
            self.running -= 1

    async def record_routing_stats(self) -> dict[str, Any]:
        """What Serve's replica actor answers ``record_routing_stats`` with: this replica's gauges
        in vLLM's exposition (the gateway's queue feed calls it on every replica, outside the
        router; Serve's controller polls it too, for request routers that want it)."""
        return {"prometheus": metrics_text(self.model, self.waiting, self.running)}

    def check_health(self) -> None:
        """Serve's per-replica health check: a replica that can answer is healthy."""


def deployment(model: str, engine_args: Mapping[str, Any], *, name: str, replicas: int, max_in_flight: int, cpus: float) -> Any:
    """The bound Serve application of the test double (``serve.run`` starts it)."""
    from ray import serve  # lazy: Serve loads only where a sweep serves a model

    return serve.deployment(
        name=name,
        num_replicas=replicas,
        max_ongoing_requests=max_in_flight,
        ray_actor_options={"num_cpus": cpus, "num_gpus": 0},
        health_check_period_s=1.0,
        health_check_timeout_s=10.0,
    )(TestDoubleServer).bind(model, dict(engine_args))
