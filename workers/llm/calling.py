"""One attempt at a model call through litellm, and what we keep of its answer.

Why shared: the gateway and the direct client must send exactly the same thing (same params,
provider retries off, hints only to test doubles) and read usage the same way. Exactly one
retry layer exists (tenacity, in the callers): litellm's ``num_retries`` and the OpenAI SDK's
``max_retries`` are both 0 here.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from workers.llm.litellm_setup import get_litellm
from workers.llm.providers import DeploymentConfig

#: litellm metadata key carrying hints to the offline test doubles (never sent to providers)
OFFLINE_METADATA_KEY = "recap_offline"


@dataclass(frozen=True)
class Attempt:
    """The parts of a provider answer we keep."""

    text: str
    finish_reason: str | None
    prompt_tokens: int | None
    cached_prompt_tokens: int
    completion_tokens: int | None
    #: litellm's own cost estimate (cross-check only), when it knows the model
    litellm_cost_usd: float | None


def litellm_kwargs(config: DeploymentConfig, messages: list[dict[str, str]], params: Mapping[str, Any],
                   *, timeout_s: float, call_key: str, hints: Mapping[str, Any] | None,
                   api_key: str | None) -> dict[str, Any]:
    kwargs: dict[str, Any] = {
        "model": config.model,
        "messages": messages,
        "timeout": timeout_s,
        "num_retries": 0,
        "max_retries": 0,
        **params,
    }
    if config.api_base:
        kwargs["api_base"] = config.api_base
    if api_key:
        kwargs["api_key"] = api_key
    elif config.api_base and not config.is_offline:
        # OpenAI-compatible self-hosted endpoints without auth: the SDK insists on some key
        kwargs["api_key"] = "no-key"
    if config.is_offline:
        kwargs["metadata"] = {
            OFFLINE_METADATA_KEY: {
                "call_key": call_key,
                "hints": dict(hints or {}),
                "options": dict(config.offline_options),
            }
        }
    return kwargs


def _usage_int(usage: Any, name: str) -> int | None:
    value = getattr(usage, name, None) if usage is not None else None
    return int(value) if isinstance(value, (int, float)) else None


def parse_response(response: Any) -> Attempt:
    choice = response.choices[0] if getattr(response, "choices", None) else None
    text = ""
    finish = None
    if choice is not None:
        text = (getattr(choice.message, "content", None) or "") if getattr(choice, "message", None) else ""
        finish = getattr(choice, "finish_reason", None)
    usage = getattr(response, "usage", None)
    cached = 0
    details = getattr(usage, "prompt_tokens_details", None) if usage is not None else None
    if details is not None:
        cached = int(getattr(details, "cached_tokens", None) or 0)
    hidden = getattr(response, "_hidden_params", None) or {}
    cost = hidden.get("response_cost")
    return Attempt(
        text=text,
        finish_reason=finish,
        prompt_tokens=_usage_int(usage, "prompt_tokens"),
        cached_prompt_tokens=cached,
        completion_tokens=_usage_int(usage, "completion_tokens"),
        litellm_cost_usd=float(cost) if isinstance(cost, (int, float)) else None,
    )


async def attempt_async(kwargs: dict[str, Any]) -> Attempt:
    response = await get_litellm().acompletion(**kwargs)
    return parse_response(response)


def attempt_sync(kwargs: dict[str, Any]) -> Attempt:
    response = get_litellm().completion(**kwargs)
    return parse_response(response)
