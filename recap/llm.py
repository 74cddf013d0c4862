"""The small client protocol between an agent and a model.

An agent hands an :class:`LLMRequest` (its window of messages plus context for the ledger) to an
:class:`LLMClient` and gets back an :class:`LLMResponse` with text, tokens, cost and latency —
or an :class:`LLMError` carrying a class. The same agent therefore runs against the Ray gateway,
a direct litellm call or a scripted test model.
"""

from __future__ import annotations

import json
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
class ToolDef:
    """A tool the model may call: its name, what it does and its arguments as a JSON schema.

    The wire shape is OpenAI's function tool (litellm translates it for Anthropic and others)."""

    name: str
    description: str = ""
    #: JSON schema of the arguments object
    parameters: Mapping[str, Any] = field(default_factory=lambda: {"type": "object", "properties": {}})

    def as_dict(self) -> dict[str, Any]:
        """The tool as litellm/OpenAI receive it."""
        return {
            "type": "function",
            "function": {"name": self.name, "description": self.description, "parameters": dict(self.parameters)},
        }


@dataclass(frozen=True)
class ToolCall:
    """One tool call of a model reply. ``arguments`` is the raw JSON string the model wrote;
    ``args`` its parsed object, or None with ``parse_error`` saying why (a model may write broken
    JSON: the agent must see that as an observation, not crash)."""

    id: str
    name: str
    arguments: str
    args: Mapping[str, Any] | None = None
    parse_error: str | None = None

    @classmethod
    def parse(cls, id: str, name: str, arguments: str) -> ToolCall:
        """A call with ``arguments`` parsed: an object, or a parse error. A call that names no
        function (a provider's null ``function``) and arguments nested deeper than
        :data:`MAX_ARGUMENT_DEPTH` are parse errors too: the JSON reader is never handed a
        nesting that would exhaust Python's recursion limit (a model can write 200,000 brackets)."""
        if not name:
            return cls(id, name, arguments, None, "the call names no function")
        depth = json_depth(arguments)
        if depth > MAX_ARGUMENT_DEPTH:
            return cls(id, name, arguments, None, f"arguments nest {depth} levels deep (at most {MAX_ARGUMENT_DEPTH} are read)")
        try:
            value = json.loads(arguments) if arguments.strip() else {}
        except (ValueError, RecursionError) as exc:
            return cls(id, name, arguments, None, f"arguments are not valid JSON: {exc}")
        if not isinstance(value, dict):
            return cls(id, name, arguments, None, f"arguments are not a JSON object but {type(value).__name__}")
        return cls(id, name, arguments, value, None)

    def as_dict(self) -> dict[str, Any]:
        """The call as an assistant message carries it on the wire (OpenAI shape)."""
        return {"id": self.id, "type": "function", "function": {"name": self.name, "arguments": self.arguments}}


#: how deep a call's arguments may nest to be read (a tool's arguments are a flat object of
#: strings and numbers; Python's JSON reader recurses once per level and fails near 1,000)
MAX_ARGUMENT_DEPTH = 64


def json_depth(text: str) -> int:
    """The deepest nesting of ``[`` / ``{`` in ``text`` outside JSON strings, in one pass without
    recursion (for text that is not JSON, the depth its brackets reach). Below
    :data:`MAX_ARGUMENT_DEPTH` it may answer the number of opening brackets instead (a bound of
    the depth that needs no pass over the text)."""
    opening = text.count("[") + text.count("{")
    if opening <= MAX_ARGUMENT_DEPTH:  # the common case, without a pass in Python
        return opening
    depth = deepest = 0
    in_string = escaped = False
    for ch in text:
        if in_string:
            if escaped:
                escaped = False
            elif ch == "\\":
                escaped = True
            elif ch == '"':
                in_string = False
        elif ch == '"':
            in_string = True
        elif ch in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif ch in "]}":
            depth = max(0, depth - 1)
    return deepest


def distinct_ids(calls: tuple[ToolCall, ...]) -> tuple[ToolCall, ...]:
    """A reply's calls with every call whose id repeats an earlier call's id made invalid (not
    run: a tool result could not say which of them it answers); the first keeps its id."""
    seen: set[str] = set()
    out = []
    for c in calls:
        if c.id in seen:
            c = ToolCall(c.id, c.name, c.arguments, None, "the call's id repeats an earlier call of the same reply")
        seen.add(c.id)
        out.append(c)
    return tuple(out)


@dataclass(frozen=True)
class ChatMessage:
    """One chat message as the provider receives it (``role``: user, assistant, system or tool).

    An assistant message may carry ``tool_calls``; a ``tool`` message answers one of them and
    names it in ``tool_call_id``."""

    role: str  # "user" | "assistant" | "system" | "tool"
    content: str
    tool_calls: tuple[ToolCall, ...] = ()
    tool_call_id: str | None = None

    def __post_init__(self) -> None:
        if self.role == "tool" and not self.tool_call_id:
            raise ValueError("a tool message needs the tool_call_id it answers")
        if self.tool_calls and self.role != "assistant":
            raise ValueError(f"only an assistant message carries tool calls, not {self.role!r}")

    def as_dict(self) -> dict[str, Any]:
        """The message in the OpenAI shape (role and content, plus the tool fields when set)."""
        out: dict[str, Any] = {"role": self.role, "content": self.content}
        if self.tool_calls:
            out["tool_calls"] = [c.as_dict() for c in self.tool_calls]
        if self.tool_call_id is not None:
            out["tool_call_id"] = self.tool_call_id
        return out


#: tool-choice settings besides naming one tool
TOOL_CHOICES = ("auto", "required", "none")


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
    #: tools the model may call (none: a plain chat request, nothing tool-related is sent)
    tools: tuple[ToolDef, ...] = ()
    #: "auto", "required", "none" or the name of one of ``tools``; None: the provider's default
    tool_choice: str | None = None
    #: the reply text's JSON schema for strict structured output, ``{"name": ..., "schema": {...}}``
    #: (ReCAP's ``{think, subtasks}`` under ``reply_schema``): the provider layer sends it as a
    #: ``json_schema`` response format where the model supports one, as ``json_object`` where it
    #: supports only that, and not at all otherwise (workers.llm.providers.DeploymentConfig.schema_params)
    response_schema: Mapping[str, Any] | None = None
    #: the episode's own cost cap (``limits.usd``, per instance; None: none) and what the episode
    #: has spent before this call: the gateway refuses a call whose worst case would pass the cap
    #: before anything is sent (a reservation, like the run's and the model's caps), so a long
    #: coding episode stops under its cap instead of one call past it. Never sent to a provider,
    #: not part of the call key or the cache fingerprint.
    episode_cap_usd: float | None = None
    episode_spent_usd: float = 0.0
    #: stop sequences sent with the request (none: the provider's default, nothing sent); part of
    #: the generation settings, so of the response cache's key
    stop: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.tool_choice is None:
            return
        if not self.tools:
            raise ValueError("tool_choice is set but the request has no tools")
        names = {t.name for t in self.tools}
        if self.tool_choice not in TOOL_CHOICES and self.tool_choice not in names:
            raise ValueError(f"tool_choice {self.tool_choice!r} is none of {TOOL_CHOICES} and no tool's name")

    def tool_params(self) -> dict[str, Any]:
        """``tools`` and ``tool_choice`` in litellm's OpenAI format (empty without tools)."""
        if not self.tools:
            return {}
        params: dict[str, Any] = {"tools": [t.as_dict() for t in self.tools]}
        if self.tool_choice in TOOL_CHOICES:
            params["tool_choice"] = self.tool_choice
        elif self.tool_choice is not None:
            params["tool_choice"] = {"type": "function", "function": {"name": self.tool_choice}}
        return params

    def stop_params(self) -> dict[str, Any]:
        """``stop`` as litellm receives it (empty without stop sequences)."""
        return {"stop": list(self.stop)} if self.stop else {}

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
    #: the tool calls of the reply, in the model's order (``text`` may then be empty)
    tool_calls: tuple[ToolCall, ...] = ()


class LLMClient(Protocol):
    """Anything that completes a request. Raises :class:`LLMError` on failure."""

    def complete(self, request: LLMRequest) -> LLMResponse: ...
