"""The rows one deployment's gateway writes for its calls: ``llm_calls`` rows and attempt ``events``.

A mixin of :class:`workers.gateway.core.DeploymentGateway`: the call path decides *what* happened,
these methods turn it into records (and the gateway's counters) in one place.
"""

from __future__ import annotations

import dataclasses
import logging
from collections import Counter
from collections.abc import Callable
from typing import Any

from recap.llm import LLMError, LLMRequest, LLMResponse
from schemas.kinds import EventKind, Severity
from schemas.records import CallRecord
from workers.gateway.call_log import CallLog
from workers.gateway.call_state import CallState, calls_of_result
from workers.llm.accounting import error_record, ok_record
from workers.llm.errors import Classified, scrub
from workers.llm.pricing import pico_to_usd
from workers.llm.providers import DeploymentConfig

#: the gateway core's logger: these lines were always logged under it
log = logging.getLogger("workers.gateway.core")


class CallRecorder:
    """Writes the gateway's records; the attributes below are set by :class:`~workers.gateway.core.DeploymentGateway`."""

    config: DeploymentConfig
    deployment: str
    test_double: bool
    call_log: CallLog
    counts: Counter[str]
    spent_pico: int
    _clock: Callable[[], float]

    def _served(self, request: LLMRequest, result: dict[str, Any], source: str, t0: float) -> LLMResponse:
        """A response recorded earlier (ledger / cache), at no cost."""
        self.counts[f"served_{source}"] += 1
        resp = LLMResponse(
            text=result["text"],
            model=self.config.model,
            prompt_tokens=int(result["prompt_tokens"]),
            cached_prompt_tokens=int(result["cached_prompt_tokens"]),
            completion_tokens=int(result["completion_tokens"]),
            cost_usd=0.0,
            latency_s=self._clock() - t0,
            retries=0,
            token_count_source=str(result["token_count_source"]),
            served_from=source,
            deployment=self.deployment,
            test_double=self.test_double,
            tool_calls=calls_of_result(result),
        )
        self._record(request, resp)
        return resp

    def _attempt_event(self, kind: EventKind, severity: Severity, call: CallState, c: Classified, attempt: int) -> None:
        """An ``events`` row per failed attempt: ``retry`` when another follows, ``call_failed``
        when the call gives up - so provider trouble that retries absorbed stays visible."""
        detail: dict[str, Any] = {
            "deployment": self.deployment,
            "call_key": call.request.call_key,
            "call_attempt": attempt,
            "kind": c.kind,
            "status": c.status_code,
            "message": scrub(c.message)[:300],
        }
        if c.retry_after_s is not None:
            detail["retry_after_s"] = c.retry_after_s
        log.info(
            "%s: %s %s of call %s (attempt %d): %s",
            self.deployment,
            kind,
            c.kind,
            call.request.call_key,
            attempt,
            detail["message"],
        )
        self.call_log.add_event(kind, severity, detail, episode_id=call.request.episode_id)

    def _fail(self, request: LLMRequest, c: Classified, t0: float, attempts: int, charged: int, source: str) -> LLMError:
        self.counts["failed"] += 1
        self.counts[f"failed_{c.kind}"] += 1
        self.spent_pico += charged
        message = scrub(c.message)
        retries = max(0, attempts - 1)
        self._add(
            error_record(
                request,
                model=self.config.model,
                kind=c.kind,
                message=message,
                cost_usd=pico_to_usd(charged),
                latency_s=self._clock() - t0,
                retries=retries,
                token_count_source=source,
                deployment=self.deployment,
                test_double=self.test_double,
            )
        )
        return LLMError(c.kind, message, retries=retries, cost_usd=pico_to_usd(charged), refusal=c.refusal)

    def _record(self, request: LLMRequest, resp: LLMResponse, cache_write_tokens: int = 0) -> None:
        self._add(ok_record(request, resp, cache_write_tokens))

    def _add(self, record: CallRecord) -> None:
        """One ``llm_calls`` row, with the model's name in the sweep beside its model string
        (``model_name``: what ``episodes.model`` holds; null for a deployment without a name)."""
        if self.config.name is not None:
            record = dataclasses.replace(record, model_name=self.config.name)
        self.call_log.add(record)
