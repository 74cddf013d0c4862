"""The small client protocol between an agent and a model.

An agent hands an :class:`LLMRequest` (its window of messages plus context for the ledger) to an
:class:`LLMClient` and gets back an :class:`LLMResponse` with text, tokens, cost and latency —
or an :class:`LLMError` carrying a class. The same agent therefore runs against the Ray gateway,
a direct litellm call or a scripted test model.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from schemas.kinds import LLM_ERROR_KINDS, LLMErrorKind
from schemas.outcomes import BudgetRefusal

#: error classes an agent may see; the gateway classifies provider errors into these
ERROR_KINDS = LLM_ERROR_KINDS


class LLMError(RuntimeError):
    """A failed model call, classified. ``kind`` is one of :data:`ERROR_KINDS`."""

    def __init__(
        self,
        kind: LLMErrorKind,
        message: str = "",
        *,
        retries: int = 0,
        cost_usd: float = 0.0,
        refusal: BudgetRefusal | None = None,
    ):
        if kind not in ERROR_KINDS:
            raise ValueError(f"unknown LLM error kind {kind!r}")
        super().__init__(f"{kind}: {message}" if message else kind)
        self.kind = kind
        self.message = message
        self.retries = retries
        self.cost_usd = cost_usd
        #: for ``budget``: the cap that refused the call (typed, so nobody parses the message)
        self.refusal = refusal


@dataclass(frozen=True)
class ChatMessage:
    """One chat message as the provider receives it (``role``: user, assistant or system)."""

    role: str  # "user" | "assistant" | "system"
    content: str

    def as_dict(self) -> dict[str, str]:
        return {"role": self.role, "content": self.content}


@dataclass(frozen=True)
class LLMRequest:
    """What an agent asks for. Only ``messages`` and generation settings reach the provider;
    the rest identifies the call for the ledger, idempotency and the offline test doubles."""

    messages: tuple[ChatMessage, ...]
    episode_id: str
    call_index: int
    purpose: str
    window_seqs: tuple[int, ...] = ()
    node_id: int | None = None
    #: the seq the reply will take in the agent's history (lets a replay find it in `messages`)
    response_seq: int | None = None
    temperature: float | None = None
    max_tokens: int | None = None
    json_mode: bool = False
    #: hints for offline test models only (expert plan, agent style); never sent to a provider
    hints: Mapping[str, Any] = field(default_factory=dict)

    @property
    def call_key(self) -> str:
        """Idempotency key: a repeated key returns the recorded result instead of paying twice."""
        return f"{self.episode_id}#{self.call_index}"


@dataclass(frozen=True)
class LLMResponse:
    """A model's answer to one call, as the agent sees it: the text, tokens, cost (USD from our
    price table), latency and retries, who counted the tokens (``token_count_source``) and where the
    answer came from (``served_from``: provider, ledger, cache or replay)."""

    text: str
    model: str
    prompt_tokens: int = 0
    cached_prompt_tokens: int = 0
    completion_tokens: int = 0
    cost_usd: float = 0.0
    latency_s: float = 0.0
    retries: int = 0
    token_count_source: str = "provider"
    served_from: str = "provider"
    deployment: str | None = None
    test_double: bool = False
    finish_reason: str | None = None
    #: litellm's own cost estimate (a cross-check; ``cost_usd`` comes from our price table)
    provider_cost_usd: float | None = None


class LLMClient(Protocol):
    """Anything that completes a request. Raises :class:`LLMError` on failure."""

    def complete(self, request: LLMRequest) -> LLMResponse: ...
