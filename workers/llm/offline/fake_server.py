"""TEST DOUBLE: a loopback OpenAI-compatible chat server with quotas and injected faults.

Why: the gateway's rate limiting, retries and error classes must be shown against a real
HTTP exchange through litellm's own client, without a paid provider. The server:

- serves ``POST /v1/chat/completions`` on 127.0.0.1 only (random port by default);
- enforces RPM/TPM over a sliding window (``window_s``; 60 s like providers, scaled down in
  tests) and answers 429 with ``Retry-After`` (seconds) and ``retry-after-ms``;
- counts tokens with the documented estimate of :mod:`workers.llm.tokens` and reports usage,
  with the prompt cache of a provider's rule (:mod:`workers.llm.prompt_cache`: ``openai``
  automatic prefixes, ``anthropic`` explicit ``cache_control`` breakpoints with writes and
  reads, ``deepseek`` hit/miss prefix units; each in that provider's own usage fields, with a
  TTL so idle episodes lose their cache), chosen per deployment: ``cache_rules`` maps a model
  name to a rule, other models get ``cache_rule`` (default ``lcp``: the longest common prefix
  with earlier prompts, chars / 4, in ``prompt_tokens_details.cached_tokens``).
  ``advance(seconds)`` moves the cache's clock (TTL tests without sleeping); message content
  may be a string or a list of text blocks (litellm's format for ``cache_control``);
- answers 400 ``context_length_exceeded`` (OpenAI error shape) above ``max_context_tokens``;
- injects latency, 5xx, hangs (timeouts), empty and malformed bodies - at random with
  ``fault_rates`` (seeded) or per request with a directive in the last message:
  ``FAKE:<mode>`` (always) or ``FAKE:<mode>*<n>`` (the first n arrivals of that exact request),
  modes: 429 500 502 503 hang ctx 400 401, the unreadable-200 modes of :data:`UNREADABLE_MODES`
  (empty malformed notjson html nochoices nullchoices nomessage nullcontent: a reply generated
  and billed, then unusable), ``textplain`` (a good reply under a text/plain content type), and
  the lying-provider modes
  ``retrylong`` (429 with ``Retry-After: long_retry_after_s``, 3600 by default), ``echokey`` (the
  reply text repeats the API key the request carried), ``negusage`` / ``zerousage`` /
  ``hugeusage`` / ``fracusage`` / ``nousage`` / ``negcached`` (the usage block reports negative, zero,
  huge, non-integer or no token counts, or negative cached tokens; the reply itself is normal);
  ``usage_override`` and these modes name the cache counts ``cached_tokens`` (reads) and
  ``cache_write_tokens`` (writes), reported in the rule's own fields;
- replies with a fixed, configurable text (truncated at ``max_tokens``, finish_reason length),
  one choice per ``n`` of the request (usage counts every choice, like OpenAI);
- ``usage_override`` replaces fields of every reply's usage block (``None`` drops a field);
  ``retry_after_s`` replaces the Retry-After of every 429;
- with ``require_api_key`` set, answers 401 echoing the wrong key it got (tests that keys are
  scrubbed before anything is written);
- keeps a log of every arrival (``GET /fake/log``), so tests check windows server-side.

Run standalone: ``python -m workers.llm.offline.fake_server --port 0 --rpm 60 --tpm 20000 --window-s 6``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import random
import re
import threading
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, cast

from aiohttp import web

from workers.llm.prompt_cache import RULES, PromptCache, normalize, usage_fields
from workers.llm.tokens import estimate_prompt_tokens, estimate_text_tokens

HOST = "127.0.0.1"
DEFAULT_REPLY = '{"think": "fake server reply", "action": "wait"}'
FAULT_MODES = (
    "429",
    "500",
    "502",
    "503",
    "hang",
    "empty",
    "malformed",
    "ctx",
    "400",
    "401",
    "retrylong",
    "echokey",
    "negusage",
    "zerousage",
    "hugeusage",
    "fracusage",
    "nousage",
    "negcached",
    "notjson",
    "html",
    "textplain",
    "nochoices",
    "nullchoices",
    "nomessage",
    "nullcontent",
)
#: modes answering HTTP 200 with a reply no client can use: a body that is not JSON (``notjson``,
#: ``html``; ``malformed`` cut mid-JSON, ``empty``), or a chat completion without a usable choice
#: (``nochoices``: ``choices: []``, ``nullchoices``: ``choices: null``, ``nomessage``: a choice
#: without ``message``, ``nullcontent``: content null and no tool calls). The provider generated the
#: reply: it bills prompt + completion (the log records the tokens it generated, so tests can
#: compute the bill). ``textplain`` (a good reply under a ``text/plain`` content type) is readable.
UNREADABLE_MODES = ("empty", "malformed", "notjson", "html", "nochoices", "nullchoices", "nomessage", "nullcontent")
#: usage blocks of the lying-provider modes (None: the field is left out)
_USAGE_FAULTS: dict[str, dict[str, Any]] = {
    "negusage": {"prompt_tokens": -1_000_000, "completion_tokens": -1_000_000},
    "zerousage": {"prompt_tokens": 0, "completion_tokens": 0},
    "hugeusage": {"prompt_tokens": 50_000_000, "completion_tokens": 50_000_000},
    "fracusage": {"prompt_tokens": 10.5, "completion_tokens": 2.25},
    "nousage": {"prompt_tokens": None, "completion_tokens": None, "cached_tokens": None, "cache_write_tokens": None},
    "negcached": {"cached_tokens": -1_000_000},
}
#: the bodies of the unreadable modes that are not JSON: (bytes, content type)
_NOT_JSON_BODIES: dict[str, tuple[bytes, str]] = {
    "empty": (b"", "application/json"),
    "malformed": (b'{"id": "chatcmpl-fake", "choices": [{"mess', "application/json"),
    "notjson": (b"upstream answered: OK", "application/json"),
    "html": (b"<html><head><title>502 Bad Gateway</title></head><body><h1>502 Bad Gateway</h1></body></html>", "text/html"),
}
#: the choices of the unreadable modes whose body is a chat completion
_CHOICE_FAULTS: dict[str, Any] = {
    "nochoices": lambda choices: [],
    "nullchoices": lambda choices: None,
    "nomessage": lambda choices: [{"index": c["index"], "finish_reason": c["finish_reason"]} for c in choices],
    "nullcontent": lambda choices: [
        {"index": c["index"], "message": {"role": "assistant", "content": None}, "finish_reason": c["finish_reason"]}
        for c in choices
    ],
}
_DIRECTIVE = re.compile(r"FAKE:([a-z0-9]+)(?:\*(\d+))?")


@dataclass
class FakeServerConfig:
    """The server's quotas, faults and caching rules (see the module docstring for each)."""

    rpm: int | None = None
    tpm: int | None = None
    window_s: float = 60.0
    latency_s: float = 0.0
    latency_jitter_s: float = 0.0
    reply: str = DEFAULT_REPLY
    max_context_tokens: int | None = None
    #: mode -> probability per request (seeded, in arrival order)
    fault_rates: dict[str, float] = field(default_factory=dict)
    seed: int = 0
    hang_s: float = 3600.0
    require_api_key: str | None = None
    #: earlier prompts kept to compute cached tokens (rules lcp and deepseek)
    prefix_memory: int = 64
    #: the prompt-cache rule of models not in ``cache_rules`` (see workers.llm.prompt_cache)
    cache_rule: str = "lcp"
    #: model name (as the request names it) -> cache rule: one rule per deployment
    cache_rules: dict[str, str] = field(default_factory=dict)
    #: seconds an unused cache entry lives (None: the rule's documented default)
    cache_ttl_s: float | None = None
    #: the smallest cacheable prefix (None: the rule's default, 1024 for openai / anthropic)
    cache_min_tokens: int | None = None
    #: keep every request body (``FakeServer.bodies``), for tests of what reaches a provider
    keep_bodies: bool = False
    #: the Retry-After (seconds) of every 429, instead of the time the window needs
    retry_after_s: float | None = None
    #: the Retry-After of the ``retrylong`` mode
    long_retry_after_s: float = 3600.0
    #: fields replacing those of every reply's usage block (prompt_tokens, completion_tokens,
    #: cached_tokens, total_tokens; None leaves the field out)
    usage_override: dict[str, Any] | None = None

    def __post_init__(self) -> None:
        bad = set(self.fault_rates) - set(FAULT_MODES)
        if bad:
            raise ValueError(f"unknown fault mode(s) {sorted(bad)}; known: {', '.join(FAULT_MODES)}")
        for rule in (self.cache_rule, *self.cache_rules.values()):
            if rule not in RULES:
                raise ValueError(f"unknown cache rule {rule!r}; known: {', '.join(RULES)}")

    def rule_for(self, model: str) -> str:
        return self.cache_rules.get(model, self.cache_rule)


@dataclass(frozen=True)
class FakeCall:
    """One arrival as the server saw it."""

    t: float  # time.monotonic() at arrival
    status: int
    mode: str
    model: str
    prompt_tokens: int
    completion_tokens: int
    cached_tokens: int
    max_tokens: int | None
    #: tokens counted against TPM (0 when the request was refused before counting)
    counted_tokens: int
    #: prompt tokens written to the cache (the anthropic rule; 0 otherwise)
    cache_write_tokens: int = 0


def window_maxima(calls: Sequence[FakeCall], window_s: float) -> tuple[int, int]:
    """The most requests and tokens that any window (t - window_s, t] held, over counted calls."""
    counted = sorted((c for c in calls if c.counted_tokens > 0), key=lambda c: c.t)
    best_n = best_tok = 0
    j = 0
    tokens = 0
    for i, c in enumerate(counted):
        tokens += c.counted_tokens
        while counted[j].t <= c.t - window_s:
            tokens -= counted[j].counted_tokens
            j += 1
        best_n = max(best_n, i - j + 1)
        best_tok = max(best_tok, tokens)
    return best_n, best_tok


def _error_body(message: str, etype: str, code: str | None, param: str | None = None) -> dict[str, Any]:
    return {"error": {"message": message, "type": etype, "param": param, "code": code}}


class FakeServer:
    """The server; use :meth:`start`/:meth:`stop` in a running loop, or :meth:`start_in_thread`."""

    def __init__(self, config: FakeServerConfig | None = None):
        self.config = config or FakeServerConfig()
        self.log: list[FakeCall] = []
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
        m = _DIRECTIVE.search(last)
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

    async def _chat(self, request: web.Request) -> web.StreamResponse:
        now = time.monotonic()
        cfg = self.config
        try:
            body = await request.json()
            messages = list(body["messages"])
            model = str(body.get("model", ""))
        except Exception:
            return web.json_response(
                _error_body("request body is not a chat completion request", "invalid_request_error", None), status=400
            )
        if cfg.keep_bodies:
            self.bodies.append(body)
        max_tokens = body.get("max_tokens") or body.get("max_completion_tokens")
        try:
            seen = normalize(messages)
        except Exception:
            return web.json_response(
                _error_body("request body is not a chat completion request", "invalid_request_error", None), status=400
            )
        prompt_tokens = estimate_prompt_tokens([{"role": m.role, "content": m.text} for m in seen])
        mode = self._mode_of(messages)

        if cfg.require_api_key is not None:
            got = request.headers.get("Authorization", "").removeprefix("Bearer ").strip()
            if got != cfg.require_api_key:
                mode = "401"
        if mode == "401":
            got = request.headers.get("Authorization", "").removeprefix("Bearer ").strip()
            self._record(now, 401, mode, model, prompt_tokens, 0, 0, max_tokens, 0)
            return web.json_response(
                _error_body(f"Incorrect API key provided: {got}.", "invalid_request_error", "invalid_api_key"), status=401
            )

        reply = cfg.reply
        finish = "stop"
        completion_tokens = estimate_text_tokens(reply)
        if max_tokens is not None and completion_tokens > int(max_tokens):
            reply = reply[: int(max_tokens) * 4]
            completion_tokens = estimate_text_tokens(reply)
            finish = "length"

        n_choices = body.get("n") or 1
        n_choices = n_choices if isinstance(n_choices, int) and n_choices >= 1 else 1
        completion_tokens *= n_choices
        if mode == "echokey":
            got = request.headers.get("Authorization", "").removeprefix("Bearer ").strip()
            reply = f"your key is {got} and {got}"
            completion_tokens = estimate_text_tokens(reply) * n_choices

        admitted = prompt_tokens + completion_tokens  # what the windows count for this request
        forced = {"429": 1.0, "retrylong": cfg.long_retry_after_s}.get(mode)
        wait = self._admit(now, admitted) if forced is None else forced
        if wait is not None:
            self._record(now, 429, mode if forced is not None else "rate_limited", model, prompt_tokens, 0, 0, max_tokens, 0)
            wait = max(wait, 0.001)
            if cfg.retry_after_s is not None and mode != "retrylong":
                wait = cfg.retry_after_s
            return web.json_response(
                _error_body("Rate limit reached for requests (fake server)", "requests", "rate_limit_exceeded"),
                status=429,
                headers={"Retry-After": str(max(1, math.ceil(wait))), "retry-after-ms": str(int(wait * 1000))},
            )

        if mode == "ctx" or (
            cfg.max_context_tokens is not None and prompt_tokens + int(max_tokens or 0) > cfg.max_context_tokens
        ):
            self._record(now, 400, "ctx", model, prompt_tokens, 0, 0, max_tokens, admitted)
            limit = cfg.max_context_tokens or 0
            return web.json_response(
                _error_body(
                    f"This model's maximum context length is {limit} tokens. However, you requested "
                    f"{prompt_tokens + int(max_tokens or 0)} tokens. Please reduce the length of the messages.",
                    "invalid_request_error",
                    "context_length_exceeded",
                    "messages",
                ),
                status=400,
            )
        if mode == "400":
            self._record(now, 400, mode, model, prompt_tokens, 0, 0, max_tokens, admitted)
            return web.json_response(
                _error_body("Invalid value for 'temperature'.", "invalid_request_error", None, "temperature"), status=400
            )

        delay = cfg.latency_s + (self._rng.uniform(0, cfg.latency_jitter_s) if cfg.latency_jitter_s else 0.0)
        if mode == "hang":
            self._record(now, 0, mode, model, prompt_tokens, 0, 0, max_tokens, admitted)
            await asyncio.sleep(cfg.hang_s)
            return web.Response(status=504)
        if delay > 0:
            await asyncio.sleep(delay)
        if mode in ("500", "502", "503"):
            self._record(now, int(mode), mode, model, prompt_tokens, 0, 0, max_tokens, admitted)
            return web.json_response(
                _error_body("The server had an error while processing your request.", "server_error", None), status=int(mode)
            )
        if mode in _NOT_JSON_BODIES:  # the reply was generated (and billed), then lost on the way
            self._record(now, 200, mode, model, prompt_tokens, completion_tokens, 0, max_tokens, admitted)
            body_bytes, content_type = _NOT_JSON_BODIES[mode]
            return web.Response(body=body_bytes, status=200, content_type=content_type)

        rule = cfg.rule_for(model)
        outcome = self.cache_for(model).serve(model, seen, now + self._clock_offset, reply=reply)
        cached, written = outcome.cached_tokens, outcome.cache_write_tokens
        self._record(
            now,
            200,
            mode if mode in _USAGE_FAULTS or mode in UNREADABLE_MODES or mode in ("echokey", "textplain") else "ok",
            model,
            prompt_tokens,
            completion_tokens,
            cached,
            max_tokens,
            admitted,
            written,
        )
        usage: dict[str, Any] = {
            "prompt_tokens": prompt_tokens,
            "completion_tokens": completion_tokens,
            "total_tokens": prompt_tokens + completion_tokens,
            "cached_tokens": cached,
            "cache_write_tokens": written if rule == "anthropic" else None,
        }
        for source in (_USAGE_FAULTS.get(mode), cfg.usage_override):
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
        payload: dict[str, Any] = {
            "id": f"chatcmpl-fake-{len(self.log)}",
            "object": "chat.completion",
            "created": int(time.time()),
            "model": model,
            "choices": [
                {"index": i, "message": {"role": "assistant", "content": reply}, "finish_reason": finish}
                for i in range(n_choices)
            ],
        }
        if usage:
            payload["usage"] = usage
        if mode in _CHOICE_FAULTS:
            payload["choices"] = _CHOICE_FAULTS[mode](payload["choices"])
        if mode == "textplain":
            return web.Response(text=json.dumps(payload), status=200, content_type="text/plain")
        return web.json_response(payload)


def main(argv: list[str] | None = None) -> None:
    """``python -m workers.llm.offline.fake_server``: serve until killed, printing the port."""
    p = argparse.ArgumentParser(description="TEST DOUBLE: loopback OpenAI-compatible chat server")
    p.add_argument("--port", type=int, default=0, help="0 = a random free port")
    p.add_argument("--rpm", type=int)
    p.add_argument("--tpm", type=int)
    p.add_argument("--window-s", type=float, default=60.0)
    p.add_argument("--latency-s", type=float, default=0.0)
    p.add_argument("--latency-jitter-s", type=float, default=0.0)
    p.add_argument("--reply", default=DEFAULT_REPLY)
    p.add_argument("--max-context-tokens", type=int)
    p.add_argument(
        "--fault",
        action="append",
        default=[],
        metavar="MODE=RATE",
        help=f"inject a fault at random; modes: {', '.join(FAULT_MODES)}",
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--require-api-key")
    p.add_argument(
        "--cache-rule", default="lcp", choices=RULES, help="prompt-cache rule of models without --model-cache-rule (default lcp)"
    )
    p.add_argument(
        "--model-cache-rule",
        action="append",
        default=[],
        metavar="MODEL=RULE",
        help="the prompt-cache rule of one model name (repeatable)",
    )
    p.add_argument("--cache-ttl-s", type=float, help="seconds an unused cache entry lives (default: the rule's)")
    args = p.parse_args(argv)
    rules = {}
    for item in args.model_cache_rule:
        name, _, rule = item.partition("=")
        rules[name] = rule
    faults = {}
    for item in args.fault:
        mode, _, rate = item.partition("=")
        faults[mode] = float(rate)
    server = FakeServer(
        FakeServerConfig(
            rpm=args.rpm,
            tpm=args.tpm,
            window_s=args.window_s,
            latency_s=args.latency_s,
            latency_jitter_s=args.latency_jitter_s,
            reply=args.reply,
            max_context_tokens=args.max_context_tokens,
            fault_rates=faults,
            seed=args.seed,
            require_api_key=args.require_api_key,
            cache_rule=args.cache_rule,
            cache_rules=rules,
            cache_ttl_s=args.cache_ttl_s,
        )
    )

    async def serve() -> None:
        url = await server.start(args.port)
        print(f"fake server listening on {url}", flush=True)
        await asyncio.Event().wait()

    try:
        asyncio.run(serve())
    except KeyboardInterrupt:
        pass


if __name__ == "__main__":
    main()
