"""``LiteLLMClient``: a Ray-free :class:`recap.llm.LLMClient` calling litellm directly.

Why: a single episode (debugging, a demo, a notebook) should not need a cluster, and the
gateway's overhead is measured against exactly this. It shares the gateway's request
building, error classes, token accounting and prices, and retries with tenacity the same way
(Retry-After honoured by sleeping) - but has no quota windows, budget ledger or cache. Rows
go to ``record_sink`` (e.g. a :class:`workers.gateway.call_log.CallLog`'s ``add``) if given.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from tenacity import (
    RetryCallState,
    Retrying,
    retry_if_exception_type,
    stop_after_attempt,
    stop_after_delay,
    wait_exponential_jitter,
)

from recap.llm import LLMError, LLMRequest, LLMResponse
from schemas.records import CallRecord
from workers.llm.accounting import Sizing, error_record, ok_record, served_from, settle, size_request, worst_case_pico
from workers.llm.cache_markers import BreakpointPlanner, mark
from workers.llm.calling import Attempt, attempt_sync, litellm_kwargs, redacted_calls
from workers.llm.errors import Classified, classify, redact_known, refused_retry_after
from workers.llm.litellm_setup import get_litellm
from workers.llm.pricing import PriceTable, pico_to_usd
from workers.llm.providers import DeploymentConfig, DeploymentConfigError, provider_messages, url_secrets

log = logging.getLogger(__name__)


class _Failed(Exception):
    def __init__(self, classified: Classified):
        super().__init__(classified.message)
        self.classified = classified


class _Retry(_Failed):
    pass


@dataclass
class _DirectCall:
    """What one call carries across its attempts."""

    request: LLMRequest
    send: list[dict[str, Any]]  # the messages as sent (cache markers where the provider wants them)
    params: dict[str, Any]
    sizing: Sizing
    t0: float
    deadline: float
    #: what an attempt that may have been billed (a timeout, an unreadable 200) is charged, as the
    #: gateway charges it: the recorded cost never reads $0 for a reply the provider billed
    worst: int
    attempts: int = 0
    charged: int = 0


class LiteLLMClient:
    """A Ray-free :class:`recap.llm.LLMClient` for one deployment (see the module docstring): the
    gateway's request building, retries, accounting and prices; each call's row goes to
    ``record_sink`` when given."""

    def __init__(
        self,
        config: DeploymentConfig,
        *,
        prices: PriceTable | None = None,
        record_sink: Callable[[CallRecord], Any] | None = None,
    ):
        self.config = config
        self.price = config.resolved_price(prices)
        self.test_double = config.is_test_double(prices)
        self.markers = BreakpointPlanner() if config.uses_cache_markers(prices) else None
        self.record_sink = record_sink
        get_litellm()  # import now (seconds), not inside the first call

    def complete(self, request: LLMRequest) -> LLMResponse:
        """One call: attempts under tenacity, then the settled response (or an :class:`LLMError`), its row to ``record_sink``."""
        call = self._new_call(request)
        try:
            attempt = self._attempts(call)
        except _Failed as exc:
            raise self._failed(call, exc.classified) from None
        return self._answered(call, attempt)

    def _new_call(self, request: LLMRequest) -> _DirectCall:
        """The call's state before its first attempt: the messages to send, the sizing, the deadline."""
        cfg = self.config
        t0 = time.monotonic()
        messages = provider_messages(request.messages)
        params = {
            **cfg.generation_params(request.temperature, request.max_tokens, request.json_mode),
            **request.tool_params(),
            **cfg.schema_params(request.response_schema),
            **request.stop_params(),
        }
        sizing = size_request(cfg.model, messages, params)
        send = mark(self.markers, request.episode_id, messages) if self.markers is not None else messages
        return _DirectCall(
            request=request,
            send=send,
            params=params,
            sizing=sizing,
            t0=t0,
            deadline=t0 + cfg.total_timeout_s,
            worst=worst_case_pico(self.price, sizing) or 0,
        )

    def _attempts(self, call: _DirectCall) -> Attempt:
        """The attempts under tenacity: Retry-After honoured by sleeping, else exponential backoff, until the deadline."""
        cfg = self.config
        request = call.request
        backoff = wait_exponential_jitter(multiplier=cfg.backoff_initial_s, max=cfg.backoff_max_s)

        def wait(rs: RetryCallState) -> float:
            exc = rs.outcome.exception() if rs.outcome else None
            if isinstance(exc, _Failed) and exc.classified.retry_after_s is not None:
                pause = exc.classified.retry_after_s
            elif isinstance(exc, _Failed) and exc.classified.kind == "rate_limit":
                pause = cfg.rate_limit_default_wait_s
            else:
                pause = backoff(rs)
            return min(pause, max(0.0, call.deadline - time.monotonic()))

        def one() -> Attempt:
            call.attempts += 1
            api_key = None
            try:
                api_key = cfg.api_key()
                timeout_s = max(0.001, min(cfg.attempt_timeout_s, call.deadline - time.monotonic()))
                return attempt_sync(
                    litellm_kwargs(
                        cfg,
                        call.send,
                        call.params,
                        timeout_s=timeout_s,
                        call_key=request.call_key,
                        hints=request.hints,
                        api_key=api_key,
                    )
                )
            except DeploymentConfigError as exc:
                raise _Failed(Classified("auth", str(exc))) from None
            except Exception as exc:
                c = classify(exc, secrets=[api_key, *url_secrets(cfg.api_base)])
                if c.maybe_billed:
                    call.charged += call.worst
                refused = refused_retry_after(c, cfg.max_retry_after_s)
                if refused is not None:
                    raise _Failed(refused) from None
                raise (_Retry if c.retryable else _Failed)(c) from None

        return Retrying(
            stop=stop_after_attempt(cfg.max_attempts) | stop_after_delay(cfg.total_timeout_s),
            wait=wait,
            retry=retry_if_exception_type(_Retry),
            reraise=True,
        )(one)

    def _failed(self, call: _DirectCall, c: Classified) -> LLMError:
        """The error a failed call raises, its row written first (cost: the attempts that may have been billed)."""
        cfg = self.config
        if self.record_sink is not None:
            self.record_sink(
                error_record(
                    call.request,
                    model=cfg.model,
                    kind=c.kind,
                    message=c.message,
                    cost_usd=pico_to_usd(call.charged),
                    latency_s=time.monotonic() - call.t0,
                    retries=call.attempts - 1,
                    token_count_source=call.sizing.counted.source,
                    deployment=cfg.deployment_name,
                    test_double=self.test_double,
                )
            )
        return LLMError(c.kind, c.message, retries=call.attempts - 1, cost_usd=pico_to_usd(call.charged))

    def _answered(self, call: _DirectCall, attempt: Attempt) -> LLMResponse:
        """The response of a successful call: checked usage and cost, the reply redacted, its row written."""
        cfg = self.config
        settled = settle(cfg.model, self.price, attempt, call.sizing)
        usage = settled.usage
        if settled.rejected:
            log.warning(
                "%s: provider usage rejected (%s); charged the worst case $%.6f",
                cfg.deployment_name,
                "; ".join(settled.problems),
                pico_to_usd(settled.cost_pico),
            )
        resp = LLMResponse(
            text=redact_known(attempt.text, cfg.secrets()),
            model=cfg.model,
            prompt_tokens=usage.prompt_tokens,
            cached_prompt_tokens=usage.cached_prompt_tokens,
            completion_tokens=usage.completion_tokens,
            cost_usd=pico_to_usd(settled.cost_pico + call.charged),
            latency_s=time.monotonic() - call.t0,
            retries=call.attempts - 1,
            token_count_source=usage.token_count_source,
            served_from=served_from(cfg.model),
            deployment=cfg.deployment_name,
            test_double=self.test_double,
            finish_reason=None if attempt.finish_reason is None else redact_known(str(attempt.finish_reason), cfg.secrets())[:64],
            provider_cost_usd=settled.provider_cost_usd,
            tool_calls=redacted_calls(attempt.tool_calls, cfg.secrets()),
        )
        if self.record_sink is not None:
            self.record_sink(ok_record(call.request, resp, usage.cache_write_tokens))
        return resp
