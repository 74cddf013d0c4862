"""Turning one provider answer into the numbers we record: tokens, their source, the cost.

Why shared: the gateway and the direct client must record the same tokens and cost for the
same answer. Provider-reported usage wins ("provider"); when a provider reports none, the
offline count stands in ("tokenizer" or "estimate"). Cost comes from the price table; a
model without a price falls back to litellm's own figure when it has one, else 0.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from schemas.records import CallRecord
from workers.llm.calling import Attempt
from workers.llm.pricing import Price, usd_to_pico
from workers.llm.tokens import TokenCount, count_text_tokens

REPLAY_MODEL = "offline/replay"


@dataclass(frozen=True)
class CallUsage:
    prompt_tokens: int
    cached_prompt_tokens: int
    completion_tokens: int
    token_count_source: str

    def as_dict(self) -> dict[str, Any]:
        return {
            "prompt_tokens": self.prompt_tokens,
            "cached_prompt_tokens": self.cached_prompt_tokens,
            "completion_tokens": self.completion_tokens,
            "token_count_source": self.token_count_source,
        }


def usage_of(model: str, attempt: Attempt, counted_prompt: TokenCount) -> CallUsage:
    if attempt.prompt_tokens is not None and attempt.completion_tokens is not None:
        return CallUsage(attempt.prompt_tokens, min(attempt.cached_prompt_tokens, attempt.prompt_tokens),
                         attempt.completion_tokens, "provider")
    completion = count_text_tokens(model, attempt.text)
    return CallUsage(counted_prompt.tokens, 0, completion.tokens, counted_prompt.source)


def cost_pico(price: Price | None, usage: CallUsage, litellm_cost_usd: float | None) -> int:
    if price is not None:
        return price.cost_pico(usage.prompt_tokens, usage.cached_prompt_tokens, usage.completion_tokens)
    if litellm_cost_usd is not None:
        return usd_to_pico(litellm_cost_usd)
    return 0


def served_from(model: str) -> str:
    return "replay" if model == REPLAY_MODEL else "provider"


def ok_record(request: Any, resp: Any) -> CallRecord:
    """The ``llm_calls`` row of a successful call (``request``: LLMRequest, ``resp``: LLMResponse)."""
    return CallRecord(
        episode_id=request.episode_id, call_index=request.call_index, call_key=request.call_key,
        purpose=request.purpose, window_seqs=tuple(request.window_seqs), model=resp.model,
        status="ok", node_id=request.node_id, response_seq=request.response_seq,
        prompt_tokens=resp.prompt_tokens, cached_prompt_tokens=resp.cached_prompt_tokens,
        completion_tokens=resp.completion_tokens, cost_usd=resp.cost_usd, latency_s=resp.latency_s,
        retries=resp.retries, token_count_source=resp.token_count_source, served_from=resp.served_from,
        deployment=resp.deployment, test_double=resp.test_double,
        finish_reason=resp.finish_reason, provider_cost_usd=resp.provider_cost_usd)


def error_record(request: Any, *, model: str, kind: str, message: str, cost_usd: float, latency_s: float,
                 retries: int, token_count_source: str, deployment: str | None,
                 test_double: bool) -> CallRecord:
    """The ``llm_calls`` row of a failed call (message already scrubbed)."""
    return CallRecord(
        episode_id=request.episode_id, call_index=request.call_index, call_key=request.call_key,
        purpose=request.purpose, window_seqs=tuple(request.window_seqs), model=model,
        status="error", node_id=request.node_id, response_seq=request.response_seq,
        error_kind=kind, error_message=message, cost_usd=cost_usd, latency_s=latency_s,
        retries=retries, token_count_source=token_count_source, served_from=served_from(model),
        deployment=deployment, test_double=test_double)
