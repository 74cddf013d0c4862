"""What one gateway call carries across its attempts, and the ways an attempt ends.

Kept apart from :mod:`workers.gateway.core` so the call's state (reservation, attempts, charges)
and its outcomes (retry, give up, served from a record) read in one place.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from recap.llm import LLMRequest, LLMResponse, ToolCall, distinct_ids
from workers.llm.accounting import Settlement, Sizing
from workers.llm.errors import Classified


class AttemptFailed(Exception):
    """An attempt failed; ``classified`` says how (kind, message, retry hints)."""

    def __init__(self, classified: Classified):
        super().__init__(classified.message)
        self.classified = classified


class Retryable(AttemptFailed):
    """A failure another attempt may cure (rate limit, server error, timeout)."""


class FinalFailure(AttemptFailed):
    """A failure that ends the call at once: no further attempt is made."""


class Served(Exception):
    """The call was answered from the ledger (idempotency) or the response cache."""

    def __init__(self, result: dict[str, Any], source: str):
        super().__init__(source)
        self.result = result
        self.source = source


@dataclass
class CallState:
    """What one call needs across its attempts."""

    request: LLMRequest
    messages: list[dict[str, str]]
    params: dict[str, Any]
    window_tokens: int
    sizing: Sizing
    worst: int | None
    cache_key: str | None
    deadline: float
    rid: int | None = None  # the live reservation
    begun: bool = False
    attempts: int = 0
    charged: int = 0  # pico charged at worst case for attempts that may have been billed
    settlement: Settlement | None = None  # the checked usage and cost of the answer
    send: list[dict[str, Any]] | None = None  # the messages as sent (cache markers); None: messages


def response_as_result(resp: LLMResponse) -> dict[str, Any]:
    """The fields of a response that a recorded result keeps (text, token counts and their source):
    what a duplicate of a call already in flight is served from, at no cost."""
    kept = ("text", "prompt_tokens", "cached_prompt_tokens", "completion_tokens", "token_count_source")
    return {**{k: getattr(resp, k) for k in kept}, **calls_as_result(resp.tool_calls)}


def calls_as_result(calls: tuple[ToolCall, ...]) -> dict[str, Any]:
    """A reply's tool calls as a recorded result keeps them (JSON-ready; nothing for a plain reply,
    so results recorded before tools existed read the same)."""
    return {"tool_calls": [{"id": c.id, "name": c.name, "arguments": c.arguments} for c in calls]} if calls else {}


def calls_of_result(result: Mapping[str, Any]) -> tuple[ToolCall, ...]:
    """The tool calls a recorded result holds, re-parsed as the reply's were (none for a plain
    reply): a replay from the ledger or the cache marks the same calls invalid."""
    return distinct_ids(
        tuple(ToolCall.parse(str(c["id"]), str(c["name"]), str(c["arguments"])) for c in result.get("tool_calls") or ())
    )
