"""The fake server itself: an aiohttp app on the loopback, its windows, caches and log."""

from __future__ import annotations

import asyncio
import json
import math
import random
import threading
import time
from collections import deque
from dataclasses import asdict, dataclass, field
from typing import Any, cast

from aiohttp import web

from workers.llm.offline.fake_server.config import FakeCall, FakeServerConfig
from workers.llm.offline.fake_server.faults import (
    CHOICE_FAULTS,
    DEEP_PLACEHOLDER,
    DIRECTIVE,
    HOSTILE_CALL_MODES,
    NOT_JSON_BODIES,
    TEXT_WITH_CALLS,
    TOOL_MODES,
    UNREADABLE_MODES,
    USAGE_FAULTS,
    deep_object_text,
    error_body,
    hostile_calls,
    placeholder_args,
)
from workers.llm.prompt_cache import PromptCache, normalize, usage_fields
from workers.llm.tokens import estimate_prompt_tokens, estimate_text_tokens

#: the only interface the server listens on
HOST = "127.0.0.1"


class FakeServer:
    """The server; use :meth:`start`/:meth:`stop` in a running loop, or :meth:`start_in_thread`."""

    def __init__(self, config: FakeServerConfig | None = None):
        self.config = config or FakeServerConfig()
        self.log: list[FakeCall] = []
        #: chat requests received so far, answered or not (``log`` records each when it is answered):
        #: a test waits on it to know its requests are at the provider
        self.arrivals = 0
        self.bodies: list[dict[str, Any]] = []
        self._window: deque[tuple[float, int]] = deque()
        self._window_tokens = 0
        self._rng = random.Random(self.config.seed)
        self._directive_counts: dict[str, int] = {}
        self._caches: dict[str, PromptCache] = {}
        self._clock_offset = 0.0
        self._runner: web.AppRunner | None = None
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self.port: int | None = None

    # ---- lifecycle ----
    @property
    def base_url(self) -> str:
        return f"http://{HOST}:{self.port}/v1"

    def _app(self) -> web.Application:
        app = web.Application(client_max_size=64 * 1024 * 1024)
        app.router.add_post("/v1/chat/completions", self._chat)
        app.router.add_get("/v1/models", self._models)
        app.router.add_get("/fake/log", self._get_log)
        app.router.add_post("/fake/reset", self._reset)
        return app

    async def start(self, port: int = 0) -> str:
        self._runner = web.AppRunner(self._app(), access_log=None, handle_signals=False, shutdown_timeout=0.2)
        await self._runner.setup()
        site = web.TCPSite(self._runner, HOST, port)
        await site.start()
        self.port = site._server.sockets[0].getsockname()[1]  # type: ignore[union-attr]
        return self.base_url

    async def stop(self) -> None:
        if self._runner is not None:
            await self._runner.cleanup()
            self._runner = None

    def start_in_thread(self, port: int = 0) -> str:
        """Serve from a daemon thread with its own event loop; returns the base URL."""
        ready = threading.Event()
        errors: list[BaseException] = []

        def run() -> None:
            loop = asyncio.new_event_loop()
            self._loop = loop
            try:
                loop.run_until_complete(self.start(port))
            except BaseException as exc:  # report to the starting thread
                errors.append(exc)
                ready.set()
                return
            ready.set()
            loop.run_forever()
            loop.run_until_complete(self.stop())
            loop.close()

        self._thread = threading.Thread(target=run, name="fake-llm-server", daemon=True)
        self._thread.start()
        ready.wait(30)
        if errors:
            raise errors[0]
        return self.base_url

    def stop_thread(self) -> None:
        if self._loop is not None and self._thread is not None:
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(10)
            self._thread = None

    def __enter__(self) -> FakeServer:
        self.start_in_thread()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop_thread()

    def reset(self) -> None:
        self.log.clear()
        self.arrivals = 0
        self.bodies.clear()
        self._window.clear()
        self._window_tokens = 0
        self._directive_counts.clear()
        self._caches.clear()
        self._clock_offset = 0.0
        self._rng = random.Random(self.config.seed)

    def advance(self, seconds: float) -> None:
        """Move the prompt cache's clock forward (entries idle longer than the TTL expire)."""
        self._clock_offset += seconds

    def cache_for(self, model: str) -> PromptCache:
        """The prompt cache of ``model``'s rule (one per rule, entries kept per model)."""
        cfg = self.config
        rule = cfg.rule_for(model)
        if rule not in self._caches:
            self._caches[rule] = PromptCache(
                rule, ttl_s=cfg.cache_ttl_s, min_tokens=cfg.cache_min_tokens, recent_prompts=cfg.prefix_memory
            )
        return self._caches[rule]

    # ---- handlers ----
    async def _models(self, request: web.Request) -> web.Response:
        return web.json_response({"object": "list", "data": [{"id": "fake-gpt", "object": "model"}]})

    async def _get_log(self, request: web.Request) -> web.Response:
        return web.json_response({"window_s": self.config.window_s, "calls": [asdict(c) for c in self.log]})

    async def _reset(self, request: web.Request) -> web.Response:
        self.reset()
        return web.json_response({"ok": True})

    def _mode_of(self, messages: list[dict[str, Any]]) -> str:
        last = str(messages[-1].get("content", "")) if messages else ""
        m = DIRECTIVE.search(last)
        if m:
            mode, times = m.group(1), m.group(2)
            if times is None:
                return mode
            key = json.dumps(messages, sort_keys=True)
            seen = self._directive_counts.get(key, 0)
            self._directive_counts[key] = seen + 1
            return mode if seen < int(times) else "ok"
        for mode, rate in self.config.fault_rates.items():
            if self._rng.random() < rate:
                return mode
        return "ok"

    def _admit(self, now: float, tokens: int) -> float | None:
        """None when the request fits the windows (and is counted), else seconds to wait."""
        cfg = self.config
        while self._window and self._window[0][0] <= now - cfg.window_s:
            self._window_tokens -= self._window.popleft()[1]
        if cfg.rpm is not None and len(self._window) >= cfg.rpm:
            return self._window[0][0] + cfg.window_s - now
        if cfg.tpm is not None and self._window_tokens + tokens > cfg.tpm:
            freed = self._window_tokens
            for t, n in self._window:
                freed -= n
                if freed + tokens <= cfg.tpm:
                    return t + cfg.window_s - now
            return cfg.window_s
        self._window.append((now, tokens))
        self._window_tokens += tokens
        return None

    def _record(
        self,
        now: float,
        status: int,
        mode: str,
        model: str,
        prompt: int,
        completion: int,
        cached: int,
        max_tokens: int | None,
        counted: int,
        written: int = 0,
    ) -> None:
        self.log.append(FakeCall(now, status, mode, model, prompt, completion, cached, max_tokens, counted, written))

    # ---- one chat completion, step by step ----
    async def _chat(self, request: web.Request) -> web.StreamResponse:
        self.arrivals += 1
        req = await self._read(request)
        if isinstance(req, web.Response):
            return req
        if req.mode == "401":
            self._record(req.now, 401, req.mode, req.model, req.prompt_tokens, 0, 0, req.max_tokens, 0)
            return web.json_response(
                error_body(f"Incorrect API key provided: {req.key}.", "invalid_request_error", "invalid_api_key"), status=401
            )
        reply = self._reply(req)
        admitted = req.prompt_tokens + reply.completion_tokens  # what the windows count for this request
        refused = self._rate_limited(req, admitted) or self._client_error(req, admitted)
        if refused is not None:
            return refused
        failed = await self._late_fault(req, reply, admitted)
        if failed is not None:
            return failed
        return self._completion(req, reply, admitted)

    async def _read(self, request: web.Request) -> _Request | web.Response:
        """The request's body, messages, prompt size and fault mode; a 400 when it is not a chat request."""
        now = time.monotonic()
        cfg = self.config
        bad = web.json_response(
            error_body("request body is not a chat completion request", "invalid_request_error", None), status=400
        )
        try:
            body = await request.json()
            messages = list(body["messages"])
            model = str(body.get("model", ""))
        except Exception:
            return bad
        if cfg.keep_bodies:
            self.bodies.append(body)
        try:
            seen = normalize(messages)
        except Exception:
            return bad
        # the messages' text, their tool calls and the tool definitions, counted as our
        # estimate counts them (a provider bills the tools it was sent)
        billed = [
            {
                "role": m.role,
                "content": m.text,
                **{k: raw[k] for k in ("tool_calls", "tool_call_id") if isinstance(raw, dict) and raw.get(k)},
            }
            for m, raw in zip(seen, messages)
        ]
        prompt_tokens = estimate_prompt_tokens(billed, body.get("tools") or None)
        mode = self._mode_of(messages)
        key = request.headers.get("Authorization", "").removeprefix("Bearer ").strip()
        if cfg.require_api_key is not None and key != cfg.require_api_key:
            mode = "401"
        max_tokens = body.get("max_tokens") or body.get("max_completion_tokens")
        return _Request(now, body, model, seen, prompt_tokens, max_tokens, mode, key)

    def _reply(self, req: _Request) -> _Reply:
        """The reply text, cut at ``max_tokens`` (finish ``length``), once per choice asked for."""
        text = self.config.reply
        finish = "stop"
        completion_tokens = estimate_text_tokens(text)
        if req.max_tokens is not None and completion_tokens > int(req.max_tokens):
            text = text[: int(req.max_tokens) * 4]
            completion_tokens = estimate_text_tokens(text)
            finish = "length"
        n_choices = req.body.get("n") or 1
        n_choices = n_choices if isinstance(n_choices, int) and n_choices >= 1 else 1
        completion_tokens *= n_choices
        if req.mode == "echokey":
            text = f"your key is {req.key} and {req.key}"
            completion_tokens = estimate_text_tokens(text) * n_choices
        calls = self._tool_calls(req)
        if req.mode in HOSTILE_CALL_MODES and (calls or req.mode == "nocalls"):
            written = json.dumps(calls)  # what the model generated, at most max_tokens of it
            completion_tokens = estimate_text_tokens(written)
            if req.max_tokens is not None:
                completion_tokens = min(completion_tokens, int(req.max_tokens))
            content = TEXT_WITH_CALLS if req.mode == "textandcalls" else None
            return _Reply(
                content or "",
                "tool_calls",
                n_choices * completion_tokens,
                n_choices,
                calls,
                content_with_calls=content,
                hostile=True,
            )
        if calls:
            completion_tokens = n_choices * sum(
                estimate_text_tokens(c["function"]["name"] + c["function"]["arguments"]) for c in calls
            )
            return _Reply("", "tool_calls", completion_tokens, n_choices, calls)
        return _Reply(text, finish, completion_tokens, n_choices)

    def _tool_calls(self, req: _Request) -> list[dict[str, Any]]:
        """The tool calls a request with ``tools`` is answered with (see ``TOOL_MODES``); none for a
        request without tools, with ``tool_choice`` "none", or in mode ``textinstead``."""
        tools = [t.get("function") or {} for t in req.body.get("tools") or [] if isinstance(t, dict)]
        choice = req.body.get("tool_choice")
        if not tools or choice == "none" or req.mode == "textinstead":
            return []
        named = choice.get("function", {}).get("name") if isinstance(choice, dict) else None
        hostile = req.mode in HOSTILE_CALL_MODES
        mode = (
            "toolcall"
            if hostile
            else req.mode
            if req.mode in TOOL_MODES
            else ("toolcall" if choice == "required" or named else None)
        )
        if mode is None:
            return []
        first = next((t for t in tools if t.get("name") == named), tools[0])
        chosen = (tools if len(tools) > 1 else tools * 2) if mode == "paralleltools" else [first]
        calls = []
        for i, tool in enumerate(chosen):
            arguments = json.dumps(placeholder_args(tool.get("parameters")))
            if mode == "badargs":
                arguments = arguments[:-1]  # the closing brace lost: not JSON
            calls.append(
                {
                    "id": f"call_fake_{len(self.log) + 1}_{i}",
                    "type": "function",
                    "function": {"name": str(tool.get("name")), "arguments": arguments},
                }
            )
        return hostile_calls(req.mode, calls) if hostile else calls

    def _rate_limited(self, req: _Request, admitted: int) -> web.Response | None:
        """A 429 with Retry-After when the request does not fit the windows (or its mode asks for one)."""
        cfg = self.config
        forced = {"429": 1.0, "retrylong": cfg.long_retry_after_s}.get(req.mode)
        wait = self._admit(req.now, admitted) if forced is None else forced
        if wait is None:
            return None
        mode = req.mode if forced is not None else "rate_limited"
        self._record(req.now, 429, mode, req.model, req.prompt_tokens, 0, 0, req.max_tokens, 0)
        wait = max(wait, 0.001)
        if cfg.retry_after_s is not None and req.mode != "retrylong":
            wait = cfg.retry_after_s
        return web.json_response(
            error_body("Rate limit reached for requests (fake server)", "requests", "rate_limit_exceeded"),
            status=429,
            headers={"Retry-After": str(max(1, math.ceil(wait))), "retry-after-ms": str(int(wait * 1000))},
        )

    def _client_error(self, req: _Request, admitted: int) -> web.Response | None:
        """A 400: the prompt and max_tokens exceed the context (``ctx``), or a bad parameter (``400``)."""
        cfg = self.config
        asked = req.prompt_tokens + int(req.max_tokens or 0)
        if req.mode == "ctx" or (cfg.max_context_tokens is not None and asked > cfg.max_context_tokens):
            self._record(req.now, 400, "ctx", req.model, req.prompt_tokens, 0, 0, req.max_tokens, admitted)
            limit = cfg.max_context_tokens or 0
            return web.json_response(
                error_body(
                    f"This model's maximum context length is {limit} tokens. However, you requested "
                    f"{asked} tokens. Please reduce the length of the messages.",
                    "invalid_request_error",
                    "context_length_exceeded",
                    "messages",
                ),
                status=400,
            )
        if req.mode == "400":
            self._record(req.now, 400, req.mode, req.model, req.prompt_tokens, 0, 0, req.max_tokens, admitted)
            return web.json_response(
                error_body("Invalid value for 'temperature'.", "invalid_request_error", None, "temperature"), status=400
            )
        return None

    async def _late_fault(self, req: _Request, reply: _Reply, admitted: int) -> web.Response | None:
        """After the latency: a hang, a 5xx, or a billed reply lost on the way (not JSON)."""
        cfg = self.config
        delay = cfg.latency_s + (self._rng.uniform(0, cfg.latency_jitter_s) if cfg.latency_jitter_s else 0.0)
        if req.mode == "hang":
            self._record(req.now, 0, req.mode, req.model, req.prompt_tokens, 0, 0, req.max_tokens, admitted)
            await asyncio.sleep(cfg.hang_s)
            return web.Response(status=504)
        if delay > 0:
            await asyncio.sleep(delay)
        if req.mode in ("500", "502", "503"):
            self._record(req.now, int(req.mode), req.mode, req.model, req.prompt_tokens, 0, 0, req.max_tokens, admitted)
            return web.json_response(
                error_body("The server had an error while processing your request.", "server_error", None), status=int(req.mode)
            )
        if req.mode in NOT_JSON_BODIES:  # the reply was generated (and billed), then lost on the way
            self._record(
                req.now, 200, req.mode, req.model, req.prompt_tokens, reply.completion_tokens, 0, req.max_tokens, admitted
            )
            body_bytes, content_type = NOT_JSON_BODIES[req.mode]
            return web.Response(body=body_bytes, status=200, content_type=content_type)
        return None

    def _completion(self, req: _Request, reply: _Reply, admitted: int) -> web.Response:
        """The chat completion: served from the model's prompt cache, with the usage the mode reports."""
        rule = self.config.rule_for(req.model)
        outcome = self.cache_for(req.model).serve(req.model, req.seen, req.now + self._clock_offset, reply=reply.text)
        cached, written = outcome.cached_tokens, outcome.cache_write_tokens
        named = (*USAGE_FAULTS, *UNREADABLE_MODES, *TOOL_MODES, *HOSTILE_CALL_MODES, "echokey", "textplain")
        # a call forced by tool_choice (no directive) is logged as ``toolcall``
        logged = req.mode if req.mode in named else ("toolcall" if reply.tool_calls else "ok")
        self._record(
            req.now, 200, logged, req.model, req.prompt_tokens, reply.completion_tokens, cached, req.max_tokens, admitted, written
        )
        payload: dict[str, Any] = {
            "id": f"chatcmpl-fake-{len(self.log)}",
            "object": "chat.completion",
            "created": int(time.time()),
            "model": req.model,
            "choices": [{"index": i, "message": reply.message(), "finish_reason": reply.finish} for i in range(reply.n_choices)],
        }
        usage = self._usage(req, reply, rule, cached, written)
        if usage:
            payload["usage"] = usage
        if req.mode in CHOICE_FAULTS:
            payload["choices"] = CHOICE_FAULTS[req.mode](payload["choices"])
        if req.mode == "textplain":
            return web.Response(text=json.dumps(payload), status=200, content_type="text/plain")
        if req.mode == "deepbody":  # the arguments object nested deeper than json.dumps writes
            body = json.dumps(payload).replace(json.dumps(DEEP_PLACEHOLDER), deep_object_text())
            return web.Response(text=body, status=200, content_type="application/json")
        return web.json_response(payload)

    def _usage(self, req: _Request, reply: _Reply, rule: str, cached: int, written: int) -> dict[str, Any]:
        """The usage block: the counted tokens, overridden by the mode's lies and the config's override,
        with the cache in the fields of the model's rule (None fields left out)."""
        usage: dict[str, Any] = {
            "prompt_tokens": req.prompt_tokens,
            "completion_tokens": reply.completion_tokens,
            "total_tokens": req.prompt_tokens + reply.completion_tokens,
            "cached_tokens": cached,
            "cache_write_tokens": written if rule == "anthropic" else None,
        }
        for source in (USAGE_FAULTS.get(req.mode), self.config.usage_override):
            for name, value in (source or {}).items():
                usage[name] = value
                if name in ("prompt_tokens", "completion_tokens") and "total_tokens" not in (source or {}):
                    usage["total_tokens"] = (
                        None
                        if None in (usage["prompt_tokens"], usage["completion_tokens"])
                        else usage["prompt_tokens"] + usage["completion_tokens"]
                    )
        cached_reported = usage.pop("cached_tokens")
        written_reported = usage.pop("cache_write_tokens")
        usage = {k: v for k, v in usage.items() if v is not None}
        if cached_reported is not None or written_reported is not None:
            usage.update(usage_fields(rule, cast(int, usage.get("prompt_tokens")), cached_reported, written_reported))
        return usage


@dataclass(frozen=True)
class _Request:
    """One chat request as the server read it."""

    now: float
    body: dict[str, Any]
    model: str
    seen: list[Any]  # the messages, normalised (workers.llm.prompt_cache.normalize)
    prompt_tokens: int
    max_tokens: Any
    mode: str
    key: str  # the bearer token it carried


@dataclass(frozen=True)
class _Reply:
    """The reply the server makes for a request, before faults."""

    text: str
    finish: str
    completion_tokens: int
    n_choices: int
    #: tool calls in the OpenAI shape (the content is then null)
    tool_calls: list[dict[str, Any]] = field(default_factory=list)
    #: a hostile mode's content beside its calls (``textandcalls``); ``nocalls``: None with no calls
    content_with_calls: str | None = None
    hostile: bool = False

    def message(self) -> dict[str, Any]:
        """The assistant message of one choice."""
        if self.tool_calls or self.hostile:
            return {"role": "assistant", "content": self.content_with_calls, "tool_calls": self.tool_calls}
        return {"role": "assistant", "content": self.text}
