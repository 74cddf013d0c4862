"""One attempt at a model call through litellm, and what we keep of its answer.

Why shared: the gateway and the direct client must send exactly the same thing (same params,
provider retries off, hints only to test doubles) and read usage the same way. Exactly one
retry layer exists (tenacity, in the callers): litellm's ``num_retries`` and the OpenAI SDK's
``max_retries`` are both 0 here.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from recap.llm import ToolCall, distinct_ids
from workers.llm.errors import UnusableReply, install_log_scrubber, redact_known
from workers.llm.litellm_setup import get_litellm
from workers.llm.offline.wire import OFFLINE_METADATA_KEY
from workers.llm.providers import DeploymentConfig

install_log_scrubber()  # the HTTP clients log request URLs: never with a base URL's credentials


@dataclass(frozen=True)
class Attempt:
    """The parts of a provider answer we keep.

    Token counts are the provider's, as integers, or None when it reported none or something
    that is not a whole number (``reported`` keeps the raw values, ``malformed`` says what
    was wrong); whether they are *plausible* is decided in :mod:`workers.llm.accounting`.

    Cache counts arrive in each provider's own fields and litellm's ``Usage`` maps them:
    OpenAI's ``prompt_tokens_details.cached_tokens`` as is, DeepSeek's
    ``prompt_cache_hit_tokens`` and Anthropic's ``cache_read_input_tokens`` to
    ``prompt_tokens_details.cached_tokens``, Anthropic's ``cache_creation_input_tokens`` to
    ``prompt_tokens_details.cache_write_tokens`` (and as an attribute of the usage itself)."""

    text: str
    finish_reason: str | None
    prompt_tokens: int | None
    cached_prompt_tokens: int
    completion_tokens: int | None
    #: litellm's own cost estimate (cross-check only), when it knows the model; may be
    #: negative or NaN when the provider's usage was (accounting refuses it)
    litellm_cost_usd: float | None
    #: the raw usage values as the provider sent them (for the event of rejected usage)
    reported: dict[str, Any] = field(default_factory=dict)
    #: what was malformed in the usage block (not a whole number, ...)
    malformed: tuple[str, ...] = ()
    #: choices in the answer (only the first is read)
    choices: int = 1
    #: prompt tokens the provider wrote to its prompt cache (Anthropic's cache_creation_input_tokens)
    cache_write_tokens: int = 0
    #: the first choice's tool calls, in order (their arguments parsed, or a parse error)
    tool_calls: tuple[ToolCall, ...] = ()


def litellm_kwargs(
    config: DeploymentConfig,
    messages: list[dict[str, Any]],
    params: Mapping[str, Any],
    *,
    timeout_s: float,
    call_key: str,
    hints: Mapping[str, Any] | None,
    api_key: str | None,
) -> dict[str, Any]:
    """The keyword arguments of one litellm call to this deployment: its params, litellm's and the
    SDK's own retries off, the endpoint and key, and for offline/ test doubles the call key, hints
    and options as metadata (hints never reach a real provider)."""
    kwargs: dict[str, Any] = {
        "model": config.model,
        "messages": messages,
        "timeout": timeout_s,
        "num_retries": 0,
        "max_retries": 0,
        **params,
    }
    if kwargs.get("tools"):
        # our tools are plain function tools, never litellm's MCP-gateway tools: skip its MCP
        # check, which imports the optional ``mcp`` package for any request with tools
        # (litellm/main.py, ``completion``, litellm 1.106)
        kwargs["_skip_mcp_handler"] = True
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


def _whole(value: Any) -> int | None:
    """``value`` as an int when it is a whole number (a float like 12.0 counts), else None."""
    if isinstance(value, bool):
        return None
    if isinstance(value, int):
        return value
    if isinstance(value, float) and math.isfinite(value) and value.is_integer():
        return int(value)
    return None


def unusable_reason(response: Any) -> str | None:
    """Why a parsed 200 answer holds no usable reply (see :class:`UnusableReply`), or None."""
    choices = getattr(response, "choices", None)
    if not choices:
        return f"the provider answered HTTP 200 with no choices ({'null' if choices is None else 'empty'})"
    message = getattr(choices[0], "message", None)
    if message is None:
        return "the provider answered HTTP 200 with a choice that has no message"
    if getattr(message, "content", None) is None and not getattr(message, "tool_calls", None):
        if getattr(choices[0], "finish_reason", None) == "tool_calls":
            return None  # the model said it called tools and called none: its (empty) reply
        return "the provider answered HTTP 200 with a message whose content is null (and no tool calls)"
    return None


def parse_response(response: Any) -> Attempt:
    """What we keep of a litellm answer (:class:`Attempt`): the first choice's text and finish
    reason, and the usage as reported. A count that is not a whole number becomes None and is listed
    in ``malformed``, for accounting to refuse. An answer without a usable reply raises
    :class:`UnusableReply`."""
    reason = unusable_reason(response)
    if reason is not None:
        raise UnusableReply(reason)
    choices = getattr(response, "choices", None) or []
    choice = choices[0]
    text = getattr(choice.message, "content", None) or ""
    tool_calls = read_tool_calls(getattr(choice.message, "tool_calls", None))
    finish = getattr(choice, "finish_reason", None)
    usage = getattr(response, "usage", None)
    details = getattr(usage, "prompt_tokens_details", None) if usage is not None else None
    raw = {
        "prompt_tokens": getattr(usage, "prompt_tokens", None) if usage is not None else None,
        "completion_tokens": getattr(usage, "completion_tokens", None) if usage is not None else None,
        "cached_tokens": getattr(details, "cached_tokens", None) if details is not None else None,
        "cache_write_tokens": _cache_writes(usage, details),
    }
    malformed = []
    if usage is None:
        malformed.append("no usage reported")
    parsed: dict[str, int | None] = {}
    for name, value in raw.items():
        parsed[name] = _whole(value)
        if value is not None and parsed[name] is None:
            malformed.append(f"{name} {value!r} is not a whole number")
    hidden = getattr(response, "_hidden_params", None) or {}
    cost = hidden.get("response_cost")
    cost = float(cost) if isinstance(cost, (int, float)) and not isinstance(cost, bool) else None
    raw["provider_cost_usd"] = cost
    return Attempt(
        text=text if isinstance(text, str) else str(text),
        finish_reason=finish,
        prompt_tokens=parsed["prompt_tokens"],
        cached_prompt_tokens=parsed["cached_tokens"] or 0,
        completion_tokens=parsed["completion_tokens"],
        litellm_cost_usd=cost,
        reported={k: (v if isinstance(v, (int, float, type(None))) else repr(v)) for k, v in raw.items()},
        malformed=tuple(malformed),
        choices=max(1, len(choices)),
        cache_write_tokens=parsed["cache_write_tokens"] or 0,
        tool_calls=tool_calls,
    )


def read_tool_calls(raw: Any) -> tuple[ToolCall, ...]:
    """A message's tool calls (litellm's OpenAI shape: objects or dicts with ``id`` and a
    ``function`` holding ``name`` and ``arguments``) as :class:`ToolCall` items, every call the
    reply made, usable or not (each is answered and recorded). Arguments that are not a string
    (some providers send the object) are kept as their JSON text; a null ``function`` is a call
    with no name (invalid, :meth:`ToolCall.parse`); a call whose id repeats an earlier one's is
    invalid (:func:`recap.llm.distinct_ids`)."""
    calls = []
    for i, item in enumerate(raw or ()):
        function = _field(item, "function")
        name = _field(function, "name")
        arguments = _field(function, "arguments")
        if arguments is None:
            arguments = ""
        elif not isinstance(arguments, str):
            try:
                arguments = json.dumps(arguments)
            except (TypeError, ValueError, RecursionError):
                arguments = str(arguments)
        call_id = _field(item, "id") or f"call_{i}"
        calls.append(ToolCall.parse(str(call_id), "" if name is None else str(name), arguments))
    return distinct_ids(tuple(calls))


def _field(item: Any, name: str) -> Any:
    """``item[name]`` for a dict, else the attribute (None when absent)."""
    if isinstance(item, Mapping):
        return item.get(name)
    return getattr(item, name, None)


def redacted_calls(calls: tuple[ToolCall, ...], secrets: list[str]) -> tuple[ToolCall, ...]:
    """The calls with known secrets cut from their arguments (as the reply text is), re-parsed."""
    out = []
    for c in calls:
        arguments = redact_known(c.arguments, secrets)
        out.append(c if arguments == c.arguments else ToolCall.parse(c.id, c.name, arguments))
    return distinct_ids(tuple(out))


def _cache_writes(usage: Any, details: Any) -> Any:
    """The cache-write count litellm parsed (None when the provider reported none)."""
    if usage is None:
        return None
    value = getattr(details, "cache_write_tokens", None) if details is not None else None
    if value is None:
        value = getattr(usage, "cache_creation_input_tokens", None)
    return value


async def attempt_async(kwargs: dict[str, Any]) -> Attempt:
    """One litellm ``acompletion`` call, parsed; provider exceptions propagate for the caller to
    classify and retry."""
    response = await get_litellm().acompletion(**kwargs)
    return parse_response(response)


def attempt_sync(kwargs: dict[str, Any]) -> Attempt:
    """One litellm ``completion`` call (blocking), parsed; provider exceptions propagate for the
    caller to classify and retry."""
    response = get_litellm().completion(**kwargs)
    return parse_response(response)
