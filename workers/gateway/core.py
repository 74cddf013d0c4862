"""The gateway of one provider deployment, in plain asyncio (the Ray actor is a thin wrapper).

Why without Ray: admission control, retries, the budget protocol and the records are the hard
parts, and they are tested here directly, against the fake server, in one process.

One call (:meth:`DeploymentGateway.complete`):
1. count the prompt offline; size the worst case (prompt bound + max output tokens);
2. attempts under tenacity (attempts, total time, per-attempt timeout). Each waits for
   admission (concurrency slot, Retry-After pause, RPM/TPM windows), then - only then, so
   queued calls hold no budget - asks the budget authority: the first attempt *begins*
   (a recorded result for this ``call_key``: idempotency, ``served_from="ledger"``; or for an
   identical request: opt-in cache, ``"cache"``; or a refusal: ``LLMError("budget")``; or a
   reservation), later ones reserve again only if the previous reservation was charged;
   then one litellm call. 429 shrinks concurrency and pauses, 5xx/timeouts back off
   exponentially; context_length, bad_request, auth return at once. An attempt that may have
   been billed (a timeout, or an HTTP 200 we cannot turn into a usable reply: a body that is not
   JSON or cut short, an HTML page, fractional token counts, no choice, a choice without a
   message, null content - :func:`workers.llm.errors.unreadable_reply`) has its reservation
   charged at worst case; the unusable 200 is a retryable ``server_error``, so a call that never
   gets a usable reply fails as one (its episode ends ``infra_error``, which a resume retries,
   under the same caps: the charges are in the ledger journal). A 200 whose tool calls are
   hostile is the model's reply, never a ``server_error``: the calls come back as the model made
   them, those that cannot run marked invalid (:mod:`workers.llm.tool_call_guard`,
   :meth:`recap.llm.ToolCall.parse`), and a body nested past any JSON reader fails the call as
   ``invalid_reply`` (charged at its reservation, not retried: the episode ends ``llm_error``,
   which no resume re-runs). After ``max_usage_rejections``
   replies whose usage was impossible, the deployment's further calls are refused
   (``LLMError("budget")`` with a ``usage`` refusal: the driver stops that model's units). The budget keeps this deployment's
   reservations, spend and cap under its name (``deployment_name``), never under the model
   string another deployment may share;
3. check the provider's usage and settle the reservation (:func:`workers.llm.accounting.settle`:
   never below our own floor; impossible usage charged at the worst case with a
   ``usage_rejected`` event), redact the deployment's secrets from the reply text, and write
   the ``llm_calls`` row (agent context from the request + accounting; the provider model
   string in ``model``, the deployment's name - the sweep's model name - in ``model_name``).
   For a provider that caches only at explicit breakpoints (``DeploymentConfig.uses_cache_markers``)
   the messages sent carry ``cache_control`` markers (:mod:`workers.llm.cache_markers`); sizing,
   fingerprints and records use the plain messages.
   A 429 whose Retry-After exceeds ``max_retry_after_s`` fails the call at once (``rate_limit``)
   instead of pausing the deployment. Every failed attempt also
   writes an ``events`` row (``retry`` or, when the call gives up, ``call_failed``, with the
   error class), so faults that retries absorbed stay visible.
"""

from __future__ import annotations

import asyncio
import time
import uuid
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

from tenacity import (
    AsyncRetrying,
    RetryCallState,
    stop_after_attempt,
    stop_after_delay,
    wait_exponential_jitter,
)

from recap.llm import LLMError, LLMRequest, LLMResponse
from schemas.outcomes import BudgetRefusal
from workers.gateway.adaptive import AdaptiveLimit, LimitChange
from workers.gateway.call_log import CallLog, run_id_of, writer_name
from workers.gateway.call_records import CallRecorder
from workers.gateway.call_state import (
    AttemptFailed,
    CallState,
    FinalFailure,
    Retryable,
    Served,
    calls_as_result,
    response_as_result,
)
from workers.gateway.ledger import BudgetLedger, EpisodeBudget, LocalBudget
from workers.gateway.limits import AdmissionController, AdmissionError, Ticket
from workers.gateway.queue_feed import QueueFeed
from workers.llm.accounting import (
    USAGE_REJECTED_EVENT,
    served_from,
    settle,
    size_request,
    worst_case_pico,
)
from workers.llm.cache_markers import BreakpointPlanner, mark
from workers.llm.calling import Attempt, attempt_async, litellm_kwargs, redacted_calls
from workers.llm.errors import Classified, classify, redact_known, refused_retry_after
from workers.llm.fingerprint import request_fingerprint
from workers.llm.litellm_setup import get_litellm
from workers.llm.pricing import PriceTable, pico_to_usd, usd_to_pico
from workers.llm.providers import DeploymentConfig, DeploymentConfigError, provider_messages, url_secrets

#: extra seconds granted to litellm's own timeout before asyncio cuts the attempt
_TIMEOUT_BACKSTOP_S = 2.0


class DeploymentGateway(CallRecorder):
    """Admission, retries, budget, idempotency, cache and records for one deployment."""

    def __init__(
        self,
        config: DeploymentConfig,
        *,
        run_dir: Path | str,
        run_id: str | None = None,
        budget: Any = None,
        prices: PriceTable | None = None,
        run_cap_usd: float | None = None,
        model_caps_usd: dict[str, float] | None = None,
        call_log: CallLog | None = None,
        durable_reservations: bool = True,
        clock: Callable[[], float] = time.monotonic,
        admission: AdmissionController | None = None,
    ):
        get_litellm()  # import now (seconds), not inside the first call
        self.config = config
        self.run_dir = Path(run_dir)
        self.run_id = run_id or run_id_of(run_dir)
        self.deployment = config.deployment_name
        self.instance = f"{self.deployment}:{uuid.uuid4().hex[:8]}"
        self.price = config.resolved_price(prices)
        self.test_double = config.is_test_double(prices)
        self.markers = BreakpointPlanner() if config.uses_cache_markers(prices) else None
        self.budget = (
            budget
            if budget is not None
            else LocalBudget(
                BudgetLedger(
                    self.run_dir,
                    run_cap_usd=run_cap_usd,
                    model_caps_usd=model_caps_usd,
                    durable_reservations=durable_reservations,
                    provider_models={self.deployment: config.model},
                )
            )
        )
        # a gateway shard brings its own (its share of a quota held elsewhere: workers.gateway.shard)
        self.admission = admission or AdmissionController(
            rpm=config.rpm,
            tpm=config.tpm,
            window_s=config.window_s,
            pad_s=config.window_pad_s,
            max_concurrency=config.max_concurrency,
            rate_limit_default_wait_s=config.rate_limit_default_wait_s,
            anchor=config.window_anchor,
            clock=clock,
            adaptive=self._adaptive_limit(config),
            on_limit=self._limit_changed,
        )
        self.call_log = call_log or CallLog(self.run_dir, self.run_id, writer_name(self.deployment))
        self._clock = clock
        self._inflight: dict[str, asyncio.Future] = {}
        self._flusher: asyncio.Task | None = None
        #: a served model's queue feed (workers.gateway.queue_feed) and its task
        self.queue_feed: QueueFeed | None = None
        self._queue_task: asyncio.Task | None = None
        self.loop: asyncio.AbstractEventLoop | None = None
        self._started = False
        self.counts: Counter[str] = Counter()
        self.errors: Counter[str] = Counter()
        self.spent_pico = 0

    # ---- lifecycle ----
    async def _ensure_started(self) -> None:
        if self._started:
            return
        self._started = True
        self.loop = asyncio.get_running_loop()
        self._flusher = self.loop.create_task(self.call_log.run_periodic_flush())
        self._start_queue_feed()
        # reservations left open by an earlier incarnation of this deployment's gateway
        adopted = await self.budget.adopt_orphans(self.deployment, self.instance)
        self.counts["orphans_adopted"] += adopted
        if adopted:
            self.call_log.add_event("orphans_charged", "warning", {"deployment": self.deployment, "reservations": adopted})

    def _start_queue_feed(self) -> None:
        """A served model's replicas' waiting requests, read while calls are in flight and fed to
        the adaptive limit (``queue_source`` set: pipeline.serving; workers.gateway.queue_feed)."""
        source = self.config.queue_source
        if source is None or self.admission.adaptive is None or self.loop is None:
            return
        from workers.serving.queue_source import queue_reader  # lazy: Ray's side, only for a served model

        self.queue_feed = QueueFeed(self.admission, queue_reader(source), source.period_s)
        self._queue_task = self.loop.create_task(self.queue_feed.run())

    async def aclose(self) -> None:
        """Flush the call rows (and close the ledger when this gateway owns it)."""
        if self._queue_task is not None:
            self._queue_task.cancel()
            try:
                await self._queue_task
            except asyncio.CancelledError:
                pass
            self._queue_task = None
        if self._flusher is not None:
            self._flusher.cancel()
            try:
                await self._flusher
            except asyncio.CancelledError:
                pass
            self._flusher = None
        self.call_log.flush()
        await self.budget.close()  # a shared budget only confirms this gateway's settlements

    @staticmethod
    def _adaptive_limit(config: DeploymentConfig) -> AdaptiveLimit | None:
        """A served model's latency-driven in-flight limit (``min_concurrency`` set: pipeline.serving)."""
        if config.min_concurrency is None:
            return None
        return AdaptiveLimit(floor=min(config.min_concurrency, config.max_concurrency), ceiling=config.max_concurrency)

    def _limit_changed(self, change: LimitChange) -> None:
        """Each change of the adaptive in-flight limit is an ``events`` row (the limit over time, in SQL)."""
        self.call_log.add_event(
            "concurrency_limit",
            "info",
            {
                "deployment": self.deployment,
                "limit": change.after,
                "before": change.before,
                "reason": change.reason,
                "latency_s": None if change.latency_s is None else round(change.latency_s, 4),
                "baseline_s": None if change.baseline_s is None else round(change.baseline_s, 4),
                "queue": change.queue,
            },
        )

    # ---- the call ----
    async def complete(self, request: LLMRequest) -> LLMResponse:
        await self._ensure_started()
        key = request.call_key
        first = self._inflight.get(key)
        if first is not None:  # the same call already in flight here: never pay twice
            t0 = self._clock()
            resp = await asyncio.shield(first)
            return self._served(request, response_as_result(resp), "ledger", t0)
        fut: asyncio.Future = asyncio.get_running_loop().create_future()
        fut.add_done_callback(lambda f: f.cancelled() or f.exception())
        self._inflight[key] = fut
        try:
            resp = await self._complete(request)
        except BaseException as exc:
            if isinstance(exc, LLMError):
                fut.set_exception(exc)
            else:
                fut.cancel()
            raise
        else:
            fut.set_result(resp)
            return resp
        finally:
            self._inflight.pop(key, None)

    async def _complete(self, request: LLMRequest) -> LLMResponse:
        t0 = self._clock()
        self.counts["calls"] += 1
        call = self._new_call(request, t0)
        try:
            attempt = await self._attempts(call)
        except Served as served:
            return self._served(request, served.result, served.source, t0)
        except AttemptFailed as exc:
            if call.rid is not None:
                await self.budget.settle(call.rid, 0, "error", None, None, None)
            if exc.classified.kind != "budget":  # a refusal is the cap at work, not a fault
                self._attempt_event("call_failed", "error", call, exc.classified, call.attempts)
            raise self._fail(request, exc.classified, t0, call.attempts, call.charged, call.sizing.counted.source) from None
        except BaseException:
            # cancelled mid-call: the provider may bill it; keep the cap safe
            if call.rid is not None:
                await self.budget.charge_worst(call.rid)
            raise
        return await self._answered(call, attempt, t0)

    def _new_call(self, request: LLMRequest, t0: float) -> CallState:
        """The call's state before its first attempt: the messages to send, the sizing, the worst case, the cache key."""
        cfg = self.config
        messages = provider_messages(request.messages)
        params = {
            **cfg.generation_params(request.temperature, request.max_tokens, request.json_mode),
            **request.tool_params(),
            **cfg.schema_params(request.response_schema),
            **request.stop_params(),
        }
        sizing = size_request(cfg.model, messages, params)
        counted = sizing.counted
        call = CallState(
            request=request,
            messages=messages,
            params=params,
            window_tokens=counted.tokens + sizing.max_tokens * sizing.choices,
            sizing=sizing,
            worst=worst_case_pico(self.price, sizing),
            cache_key=request_fingerprint(cfg.model, params, messages) if cfg.cache else None,
            deadline=t0 + cfg.total_timeout_s,
        )
        if self.markers is not None:
            call.send = mark(self.markers, request.episode_id, messages)
        return call

    async def _answered(self, call: CallState, attempt: Attempt, t0: float) -> LLMResponse:
        """Settle a successful call: its checked usage and cost, its redacted reply, its reservation and its row."""
        cfg = self.config
        request = call.request
        settled = call.settlement or settle(cfg.model, self.price, attempt, call.sizing)
        usage, cost = settled.usage, settled.cost_pico
        if settled.rejected:  # impossible usage: charged at the worst case, visible as an event
            self.counts["usage_rejected"] += 1  # past max_usage_rejections: no more calls (_untrusted)
            self.call_log.add_event(
                USAGE_REJECTED_EVENT,
                "error",
                {"deployment": self.deployment, "call_key": request.call_key, **settled.event_detail()},
                episode_id=request.episode_id,
            )
        # a reply that echoes the API key or the base URL's credentials is stored and returned
        # without them (ledger, cache, records and the agent all see the redacted text)
        secrets = self._secrets()
        text = redact_known(attempt.text, secrets)
        finish = None if attempt.finish_reason is None else redact_known(str(attempt.finish_reason), secrets)[:64]
        tool_calls = redacted_calls(attempt.tool_calls, secrets)
        result = {"text": text, "finish_reason": finish, **usage.as_dict(), **calls_as_result(tool_calls)}
        assert call.rid is not None  # admitted: it holds a reservation
        await self.budget.settle(call.rid, cost, "ok", result, call.cache_key, settled.provider_cost_usd)
        total = cost + call.charged
        self.spent_pico += total
        self.counts["ok"] += 1
        resp = LLMResponse(
            text=text,
            model=cfg.model,
            prompt_tokens=usage.prompt_tokens,
            cached_prompt_tokens=usage.cached_prompt_tokens,
            completion_tokens=usage.completion_tokens,
            cost_usd=pico_to_usd(total),
            latency_s=self._clock() - t0,
            retries=call.attempts - 1,
            token_count_source=usage.token_count_source,
            served_from=served_from(cfg.model),
            deployment=self.deployment,
            test_double=self.test_double,
            finish_reason=finish,
            provider_cost_usd=settled.provider_cost_usd,
            tool_calls=tool_calls,
        )
        self._record(request, resp, usage.cache_write_tokens)
        return resp

    async def _attempts(self, call: CallState) -> Attempt:
        """The call's attempts: the first one bare, retries (if it fails retryably) under :meth:`_retries`.

        Why the first attempt outside tenacity: almost every call succeeds at once, and building
        tenacity's retry state and running its action chain around each attempt was about 3 % of
        the gateway's CPU per call (issue 37). Only ``Retryable`` failures go on to the retries;
        every other outcome (an answer, ``FinalFailure``, ``Served``, a cancellation) leaves
        here as it leaves tenacity (``retry_if_exception_type(Retryable)``)."""
        start = time.monotonic()  # tenacity's clock for stop_after_delay (RetryCallState.start_time)
        try:
            return await self._one_attempt(call)
        except Retryable as exc:
            return await self._retries(call, start, exc)

    async def _retries(self, call: CallState, start: float, failure: Retryable) -> Attempt:
        """Attempts 2.. after ``failure`` (attempt 1), as tenacity's ``AsyncRetrying`` ran them with
        ``stop_after_attempt(max_attempts) | stop_after_delay(total_timeout_s)``, the wait below,
        ``reraise=True`` and a ``retry`` event before each sleep: the stop and wait strategies are
        tenacity's own objects, read through a ``RetryCallState`` started at ``start``."""
        cfg = self.config
        backoff = wait_exponential_jitter(multiplier=cfg.backoff_initial_s, max=cfg.backoff_max_s)
        stop = stop_after_attempt(cfg.max_attempts) | stop_after_delay(cfg.total_timeout_s)
        rs = RetryCallState(AsyncRetrying(stop=stop, wait=backoff, reraise=True), None, (), {})  # built on a retry only
        rs.start_time = start
        while True:
            rs.set_exception((type(failure), failure, failure.__traceback__))
            if stop(rs):
                raise failure  # reraise=True: the last attempt's own failure
            if failure.classified.kind == "rate_limit":
                sleep = 0.0  # admission holds every attempt until the Retry-After pause ends
            else:
                sleep = min(backoff(rs), max(0.0, call.deadline - self._clock()))
            self._attempt_event("retry", "warning", call, failure.classified, rs.attempt_number)
            await asyncio.sleep(sleep)
            rs.prepare_for_next_attempt()
            try:
                return await self._one_attempt(call)
            except Retryable as exc:
                failure = exc

    async def _admit_and_reserve(self, call: CallState) -> Ticket:
        """Wait for admission, then make sure the attempt is covered by a reservation.

        The budget is asked only once the attempt may be sent, so calls queued behind the
        concurrency limit or the windows do not hold reservations (they would starve the cap).
        The first attempt asks ``begin`` (which may answer with a recorded result instead)."""
        cfg = self.config
        untrusted = self._untrusted()
        if untrusted is not None:
            raise FinalFailure(Classified("budget", untrusted.message, refusal=untrusted))
        remaining = call.deadline - self._clock()
        if remaining <= 0:
            raise FinalFailure(Classified("timeout", f"total timeout {cfg.total_timeout_s}s reached"))
        try:
            ticket = await asyncio.wait_for(self.admission.acquire(call.window_tokens), remaining)
        except AdmissionError as exc:
            raise FinalFailure(Classified("bad_request", str(exc))) from None
        except TimeoutError:
            raise FinalFailure(Classified("timeout", f"no capacity within the total timeout {cfg.total_timeout_s}s")) from None
        key = call.request.call_key
        try:
            episode = self._episode_budget(call)
            if not call.begun:
                answer = await self.budget.begin(key, self.deployment, call.worst, call.cache_key, self.instance, episode)
                call.begun = True
            elif call.rid is None:
                answer = await self.budget.reserve(key, self.deployment, call.worst, self.instance, episode)
            else:
                return ticket
        except BaseException:
            self.admission.cancel(ticket)
            raise
        if answer["status"] == "reserved":
            call.rid = answer["rid"]
            return ticket
        self.admission.cancel(ticket)  # nothing is sent
        if answer["status"] == "recorded":
            raise Served(answer["result"], answer["served_from"])
        refusal = answer.get("refusal")
        raise FinalFailure(
            Classified("budget", answer["message"], refusal=BudgetRefusal.from_dict(refusal) if refusal is not None else None)
        )

    @staticmethod
    def _episode_budget(call: CallState) -> EpisodeBudget | None:
        """The episode's cap and its spend so far (pico-USD) for this attempt's reservation: what
        the episode spent before the call plus what earlier attempts of the call were charged."""
        cap = call.request.episode_cap_usd
        if cap is None:
            return None
        return (usd_to_pico(cap), usd_to_pico(call.request.episode_spent_usd) + call.charged)

    async def _one_attempt(self, call: CallState) -> Attempt:
        cfg = self.config
        call.attempts += 1
        if call.attempts > 1:
            self.counts["retries"] += 1
        ticket = await self._admit_and_reserve(call)
        api_key: str | None = None
        try:
            api_key = cfg.api_key()
            timeout_s = max(0.001, min(cfg.attempt_timeout_s, call.deadline - self._clock()))
            kwargs = litellm_kwargs(
                cfg,
                call.send or call.messages,
                call.params,
                timeout_s=timeout_s,
                call_key=call.request.call_key,
                hints=call.request.hints,
                api_key=api_key,
            )
            attempt = await asyncio.wait_for(attempt_async(kwargs), timeout_s + _TIMEOUT_BACKSTOP_S)
        except DeploymentConfigError as exc:
            self.admission.cancel(ticket)
            raise FinalFailure(Classified("auth", str(exc))) from None
        except asyncio.CancelledError:
            self.admission.release(ticket, "cancelled")
            raise
        except Exception as exc:
            c = classify(exc, secrets=[api_key, *self._url_secrets])
            refused = refused_retry_after(c, cfg.max_retry_after_s)
            # a Retry-After beyond the cap does not pause the deployment (nobody waits an hour)
            self.admission.release(ticket, c.kind, retry_after_s=c.retry_after_s, pause=refused is None)
            self.errors[c.kind] += 1
            if c.maybe_billed and call.rid is not None:
                call.charged += await self.budget.charge_worst(call.rid)
                call.rid = None
            if refused is not None:
                self.counts["retry_after_refused"] += 1
                raise FinalFailure(refused) from None
            raise (Retryable if c.retryable else FinalFailure)(c) from None
        actual = output = None  # the token window learns the reported usage only when it is plausible
        try:
            call.settlement = settled = settle(cfg.model, self.price, attempt, call.sizing)
            if not settled.rejected and settled.usage.token_count_source == "provider":
                actual = settled.usage.prompt_tokens + settled.usage.completion_tokens
                output = settled.usage.completion_tokens  # a served model's limit counts latency per output token
        finally:
            self.admission.release(ticket, "ok", actual_tokens=actual, output_tokens=output)
        return attempt

    def _untrusted(self) -> BudgetRefusal | None:
        """A ``usage`` refusal once ``max_usage_rejections`` replies of this deployment had impossible
        usage: each was charged at its worst case, and a provider that keeps lying about what it
        bills is not called again this session (the calls in flight finish). The refusal names the
        limit that was reached, not the running count: calls already in flight when it is reached
        may add a rejection or two (each its own ``usage_rejected`` event), and the stop reason a
        run prints and records must not depend on that timing."""
        limit = self.config.max_usage_rejections
        if self.counts["usage_rejected"] < limit:
            return None
        self.counts["usage_refused"] += 1
        return BudgetRefusal("usage", self.deployment, rejected=limit)

    # ---- secrets ----
    @property
    def _url_secrets(self) -> list[str]:
        return url_secrets(self.config.api_base)

    def _secrets(self) -> list[str]:
        """The deployment's secret values (API key, base-URL credentials), read now."""
        return self.config.secrets()

    # ---- control ----
    def pause(self) -> None:
        self.admission.pause()

    def resume(self) -> None:
        self.admission.resume()

    def set_limits(self, *, rpm: int | None = None, tpm: int | None = None, max_concurrency: int | None = None) -> None:
        self.admission.set_limits(rpm=rpm, tpm=tpm, max_concurrency=max_concurrency)

    def stats(self) -> dict[str, Any]:
        return {
            "deployment": self.deployment,
            "model": self.config.model,
            "calls": dict(self.counts),
            "errors": dict(self.errors),
            "spent_usd": pico_to_usd(self.spent_pico),
            "rows_written": self.call_log.rows_written,
            "rows_pending": self.call_log.pending,
            "inflight": len(self._inflight),
            **self.admission.stats(),
        }
