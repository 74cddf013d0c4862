"""Turning one provider answer into the numbers we record: tokens, their source, the cost.

Why shared: the gateway and the direct client must record the same tokens and cost for the
same answer, and neither may let a provider's word lower what a call is charged.

Before a call (:func:`size_request`): the prompt is counted offline, bounded from above
(:func:`workers.llm.tokens.prompt_token_bound`), and the output is bounded by ``max_tokens``
x choices (always 1: ``n``/``best_of`` other than 1 are refused by the deployment config; the
bound still multiplies, should one ever get through) + :data:`COMPLETION_SLACK_TOKENS`. The
worst case (:func:`worst_case_pico`, what the budget reserves) is that bound at full prices:
every prompt token at the dearest input price, which is the cache-write price where a provider
bills writes above the input price (Anthropic: 1.25x), so a cap holds even when a whole prompt
is written to the cache.

After a call (:func:`settle`), the provider's usage is *checked*. It is **impossible** when:
- it is missing, or a count is not a whole number (litellm reports missing usage as zeros,
  which the next rule catches);
- a count is negative, or cached (read) + cache-write prompt tokens exceed the prompt tokens;
- the prompt tokens are below ``ceil(our count / PROMPT_FLOOR_DIVISOR)`` (no tokenizer packs 4x
  more text per token than our count assumes: zero is always impossible) or above our upper
  bound of the prompt;
- the completion tokens exceed ``max_tokens`` x choices + the slack, or are below
  ``ceil(our count of the reply text / PROMPT_FLOOR_DIVISOR)`` (a non-empty reply takes >= 1);
- litellm's cost figure for it (``provider_cost_usd``) is negative, NaN or infinite.
An impossible answer is charged its **worst case** (the reservation: the cap stays safe and
the call costs at least what it could have), recorded with our own token counts, and the
gateway writes a ``usage_rejected`` event. Plausible usage is charged
``max(cost of the provider's usage, floor)``, the **floor** being our own count of the prompt
at the input price (the part the provider reports as cached at the cached price) + our own
count of the reply text (at least 1 token, at most the output bound) at the output price - so
under-reported usage never lowers spend. Every settled cost lies between the floor and the
worst case. The provider's usage is priced exactly: uncached prompt tokens at the input
price, cached (read) ones at the cached price, cache-write ones at the write price, the
completion at the output price (:meth:`workers.llm.pricing.Price.cost_pico`). A model without
a price is charged litellm's figure when that is a valid (finite, >= 0) number, else 0 (such a
model cannot run under a cap).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Final

from recap.llm import LLMRequest, LLMResponse
from schemas.kinds import LLMErrorKind
from schemas.records import CallRecord
from workers.llm.calling import Attempt
from workers.llm.pricing import Price, usd_to_pico
from workers.llm.tokens import TokenCount, count_prompt_tokens, count_text_tokens, prompt_token_bound

#: completion tokens a provider may report beyond max_tokens (a stop token); reserved too
COMPLETION_SLACK_TOKENS = 2
#: reported prompt / completion tokens below our own count divided by this are impossible
PROMPT_FLOOR_DIVISOR = 4
#: the event kind of an answer whose usage (or cost figure) was refused
USAGE_REJECTED_EVENT: Final = "usage_rejected"

REPLAY_MODEL = "offline/replay"


@dataclass(frozen=True)
class CallUsage:
    """The token counts a call is recorded with: the provider's when its usage passed the checks
    (``token_count_source`` ``provider``), else our own counts of the prompt and the reply."""

    prompt_tokens: int
    cached_prompt_tokens: int
    completion_tokens: int
    token_count_source: str
    #: prompt tokens written to the provider's prompt cache (a part of prompt_tokens)
    cache_write_tokens: int = 0

    def as_dict(self) -> dict[str, Any]:
        return {
            "prompt_tokens": self.prompt_tokens,
            "cached_prompt_tokens": self.cached_prompt_tokens,
            "completion_tokens": self.completion_tokens,
            "token_count_source": self.token_count_source,
            "cache_write_tokens": self.cache_write_tokens,
        }


def output_choices(params: Mapping[str, Any]) -> int:
    """Choices a provider generates (and bills) for these params: the largest of n / best_of."""
    out = 1
    for name in ("n", "best_of"):
        value = params.get(name)
        if isinstance(value, int) and not isinstance(value, bool) and value > out:
            out = value
    return out


@dataclass(frozen=True)
class Sizing:
    """What is known of a request before it is sent."""

    counted: TokenCount  # our prompt count (best guess)
    prompt_bound: int  # upper bound of the prompt tokens any provider bills
    max_tokens: int  # max_tokens per choice
    choices: int  # output_choices(params)

    @property
    def output_bound(self) -> int:
        """Completion tokens a plausible answer may report (all choices + slack)."""
        return self.max_tokens * self.choices + COMPLETION_SLACK_TOKENS


def size_request(
    model: str, messages: list[dict[str, Any]], params: Mapping[str, Any], counted: TokenCount | None = None
) -> Sizing:
    """What is known of a request before it is sent (:class:`Sizing`): our prompt count
    (``counted``, when the caller already has it), its upper bound, ``max_tokens`` (``params`` must
    hold it) and the choices."""
    tools = params.get("tools") or None
    counted = counted or count_prompt_tokens(model, messages, tools)
    bound = prompt_token_bound(model, messages, counted, tools)
    return Sizing(counted, bound, int(params["max_tokens"]), output_choices(params))


def worst_case_pico(price: Price | None, sizing: Sizing) -> int | None:
    """The most a call of this size can cost (what the budget reserves); None without a price."""
    if price is None:
        return None
    return sizing.prompt_bound * price.max_input_rate() + sizing.output_bound * price.rates()[2]


def valid_cost_usd(value: Any) -> float | None:
    """A provider/litellm cost figure when it is a finite number >= 0, else None."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    value = float(value)
    return value if math.isfinite(value) and value >= 0 else None


@dataclass(frozen=True)
class Settlement:
    """What one answer is charged and recorded as."""

    usage: CallUsage
    cost_pico: int
    #: why the provider's usage / cost was refused (empty: accepted)
    problems: tuple[str, ...] = ()
    floor_pico: int = 0
    worst_pico: int | None = None
    #: litellm's cost figure when valid (recorded as the cross-check), else None
    provider_cost_usd: float | None = None
    reported: dict[str, Any] = field(default_factory=dict)

    @property
    def rejected(self) -> bool:
        return bool(self.problems)

    def event_detail(self) -> dict[str, Any]:
        """The ``usage_rejected`` event's detail (no text, no secrets: numbers only)."""
        return {
            "problems": list(self.problems),
            "reported": dict(self.reported),
            "charged_usd": self.cost_pico / 1e12,
            "worst_case_usd": None if self.worst_pico is None else self.worst_pico / 1e12,
            "floor_usd": self.floor_pico / 1e12,
        }


def usage_problems(attempt: Attempt, sizing: Sizing, reply_tokens: int) -> list[str]:
    """Why the provider's usage of this answer cannot be true (empty: plausible)."""
    problems = list(attempt.malformed)
    p, c, cached = attempt.prompt_tokens, attempt.completion_tokens, attempt.cached_prompt_tokens
    if p is None or c is None:
        if not any(x.startswith(("no usage", "prompt_tokens", "completion_tokens")) for x in problems):
            problems.append("token counts missing")
    if p is not None:
        low = max(1, math.ceil(sizing.counted.tokens / PROMPT_FLOOR_DIVISOR))
        if p < 0:
            problems.append(f"prompt_tokens {p} is negative")
        elif p < low:
            problems.append(f"prompt_tokens {p} below {low} (our count {sizing.counted.tokens} / {PROMPT_FLOOR_DIVISOR})")
        elif p > sizing.prompt_bound:
            problems.append(f"prompt_tokens {p} above our upper bound {sizing.prompt_bound}")
    if c is not None:
        low = math.ceil(min(reply_tokens, sizing.output_bound) / PROMPT_FLOOR_DIVISOR)
        if c < 0:
            problems.append(f"completion_tokens {c} is negative")
        elif c < low:
            problems.append(f"completion_tokens {c} below {low} (our count of the reply {reply_tokens} / {PROMPT_FLOOR_DIVISOR})")
        elif c > sizing.output_bound:
            problems.append(
                f"completion_tokens {c} above max_tokens {sizing.max_tokens} x {sizing.choices} "
                f"choice(s) + {COMPLETION_SLACK_TOKENS}"
            )
    written = attempt.cache_write_tokens
    if cached < 0:
        problems.append(f"cached prompt tokens {cached} is negative")
    elif p is not None and p >= 0 and cached > p:
        problems.append(f"cached prompt tokens {cached} above prompt_tokens {p}")
    if written < 0:
        problems.append(f"cache-write prompt tokens {written} is negative")
    elif p is not None and p >= 0 and 0 <= cached <= p and cached + written > p:
        problems.append(f"cached {cached} + cache-write {written} prompt tokens above prompt_tokens {p}")
    cost = attempt.litellm_cost_usd
    if cost is not None and valid_cost_usd(cost) is None:
        problems.append(f"provider cost {cost!r} is not a finite amount >= 0")
    return problems


def settle(model: str, price: Price | None, attempt: Attempt, sizing: Sizing) -> Settlement:
    """Check the provider's usage of one answer and price it (see the module doc)."""
    reply = count_text_tokens(model, attempt.text)
    problems = usage_problems(attempt, sizing, reply.tokens)
    worst = worst_case_pico(price, sizing)
    provider_cost = valid_cost_usd(attempt.litellm_cost_usd)
    reply_floor = min(max(1, reply.tokens), sizing.output_bound)
    counted = sizing.counted
    if problems:
        usage = CallUsage(counted.tokens, 0, reply.tokens, counted.source)
        floor = 0 if price is None else price.cost_pico(counted.tokens, 0, reply_floor)
        cost = worst if worst is not None else 0
        return Settlement(usage, cost, tuple(problems), floor, worst, provider_cost, dict(attempt.reported))
    assert attempt.prompt_tokens is not None and attempt.completion_tokens is not None
    usage = CallUsage(
        attempt.prompt_tokens, attempt.cached_prompt_tokens, attempt.completion_tokens, "provider", attempt.cache_write_tokens
    )
    if price is None:
        cost = usd_to_pico(provider_cost) if provider_cost is not None else 0
        return Settlement(usage, cost, (), 0, None, provider_cost, dict(attempt.reported))
    floor = price.cost_pico(counted.tokens, min(usage.cached_prompt_tokens, counted.tokens), reply_floor)
    cost = max(
        price.cost_pico(usage.prompt_tokens, usage.cached_prompt_tokens, usage.completion_tokens, usage.cache_write_tokens), floor
    )
    return Settlement(usage, cost, (), floor, worst, provider_cost, dict(attempt.reported))


def cost_pico(price: Price | None, usage: CallUsage, litellm_cost_usd: float | None) -> int:
    """The cost of known usage (no checks: :func:`settle` is what calls are charged by)."""
    if price is not None:
        return price.cost_pico(usage.prompt_tokens, usage.cached_prompt_tokens, usage.completion_tokens, usage.cache_write_tokens)
    valid = valid_cost_usd(litellm_cost_usd)
    return usd_to_pico(valid) if valid is not None else 0


def served_from(model: str) -> str:
    """The ``served_from`` of a provider answer: ``replay`` for the offline/replay test double, else
    ``provider``."""
    return "replay" if model == REPLAY_MODEL else "provider"


def ok_record(request: LLMRequest, resp: LLMResponse, cache_write_tokens: int = 0) -> CallRecord:
    """The ``llm_calls`` row of a successful call (the response carries no cache writes, so the
    caller passes them from the settlement)."""
    return CallRecord(
        episode_id=request.episode_id,
        call_index=request.call_index,
        call_key=request.call_key,
        purpose=request.purpose,
        window_seqs=tuple(request.window_seqs),
        model=resp.model,
        status="ok",
        node_id=request.node_id,
        response_seq=request.response_seq,
        prompt_tokens=resp.prompt_tokens,
        cached_prompt_tokens=resp.cached_prompt_tokens,
        completion_tokens=resp.completion_tokens,
        cost_usd=resp.cost_usd,
        latency_s=resp.latency_s,
        retries=resp.retries,
        token_count_source=resp.token_count_source,
        served_from=resp.served_from,
        deployment=resp.deployment,
        test_double=resp.test_double,
        finish_reason=resp.finish_reason,
        provider_cost_usd=resp.provider_cost_usd,
        cache_write_tokens=cache_write_tokens,
    )


def error_record(
    request: LLMRequest,
    *,
    model: str,
    kind: LLMErrorKind,
    message: str,
    cost_usd: float,
    latency_s: float,
    retries: int,
    token_count_source: str,
    deployment: str | None,
    test_double: bool,
) -> CallRecord:
    """The ``llm_calls`` row of a failed call (message already scrubbed)."""
    return CallRecord(
        episode_id=request.episode_id,
        call_index=request.call_index,
        call_key=request.call_key,
        purpose=request.purpose,
        window_seqs=tuple(request.window_seqs),
        model=model,
        status="error",
        node_id=request.node_id,
        response_seq=request.response_seq,
        error_kind=kind,
        error_message=message,
        cost_usd=cost_usd,
        latency_s=latency_s,
        retries=retries,
        token_count_source=token_count_source,
        served_from=served_from(model),
        deployment=deployment,
        test_double=test_double,
    )
