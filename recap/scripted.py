"""A scripted model: returns preset replies in order. Used to render demonstrations (the agent
replays the demonstration's replies on the demonstration environment) and in tests.

It is a test double in the records (``test_double=True``); it never pretends to be a provider.
Token counts are a plain estimate (characters / 4) so accounting paths get exercised.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from recap.llm import LLMError, LLMRequest, LLMResponse

#: a reply text, a JSON object, an error to raise, a whole response (e.g. one cut at the output
#: cap), or a function of the request returning any of these
Item = str | Mapping[str, Any] | LLMError | LLMResponse | Callable[[LLMRequest], Any]


class ScriptExhausted(RuntimeError):
    """The agent asked for more replies than the script holds."""


def estimate_tokens(text: str) -> int:
    """The scripted model's token estimate: ceil(characters / 4), at least 1 (no tokenizer in the
    pure core)."""
    return max(1, (len(text) + 3) // 4)


class ScriptedClient:
    """A test-double :class:`~recap.llm.LLMClient` answering each call with the next scripted
    :data:`Item`; keeps every request in ``requests`` and raises ScriptExhausted when the script
    runs out."""

    def __init__(
        self,
        replies: Iterable[Item],
        *,
        model: str = "scripted",
        cost_per_1k_tokens: float = 0.0,
    ) -> None:
        self._replies = list(replies)
        self._pos = 0
        self.model = model
        self.cost_per_1k_tokens = cost_per_1k_tokens
        self.requests: list[LLMRequest] = []

    @property
    def remaining(self) -> int:
        return len(self._replies) - self._pos

    def complete(self, request: LLMRequest) -> LLMResponse:
        self.requests.append(request)
        if self._pos >= len(self._replies):
            raise ScriptExhausted(
                f"script of {len(self._replies)} replies exhausted at call {request.call_index} ({request.purpose})"
            )
        item: Any = self._replies[self._pos]
        self._pos += 1
        if callable(item) and not isinstance(item, LLMError):
            item = item(request)
        if isinstance(item, LLMError):
            raise item
        if isinstance(item, LLMResponse):
            return item
        text = item if isinstance(item, str) else json.dumps(dict(item), ensure_ascii=False)
        prompt_tokens = sum(estimate_tokens(m.content) for m in request.messages)
        completion_tokens = estimate_tokens(text)
        return LLMResponse(
            text=text,
            model=self.model,
            prompt_tokens=prompt_tokens,
            completion_tokens=completion_tokens,
            cost_usd=(prompt_tokens + completion_tokens) * self.cost_per_1k_tokens / 1000,
            token_count_source="estimate",
            served_from="replay",
            test_double=True,
        )
