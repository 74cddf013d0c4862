"""A test double served over HTTP: the ``offline/`` provider forwarding a call to a served copy.

Why: a sweep may serve a test double itself (``serve: {engine: test-double}``, Ray Serve:
:mod:`workers.serving.test_double`). The call then leaves the gateway's process like a real
provider's - over HTTP, to a replica that may die - while the model string stays ``offline/...``
(labelled a test double everywhere). The offline provider forwards here when its ``api_base``
is an ``http(s)://`` URL; the hints, call key and options travel in the request body under
:data:`workers.llm.offline.wire.OFFLINE_METADATA_KEY` (never sent to a real provider: only an
``offline/`` model takes this path).

An HTTP failure is raised with its status (a replica lost mid-call: 5xx, a refused connection:
503), so the gateway classifies it as a ``server_error`` and retries it like a provider's.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from workers.llm.offline.expert_tools import ToolAnswer
from workers.llm.offline.wire import OFFLINE_METADATA_KEY


def is_served(api_base: str | None) -> bool:
    """Whether a test double's ``api_base`` names a served copy (else: a folder, or nothing)."""
    return bool(api_base) and str(api_base).startswith(("http://", "https://"))


class RemoteError(Exception):
    """The served copy failed; ``status_code`` is its HTTP status (503: not reachable)."""

    def __init__(self, status_code: int, message: str) -> None:
        super().__init__(message)
        self.status_code = status_code
        self.message = message


@dataclass(frozen=True)
class RemoteAnswer:
    """The served copy's reply and its usage as it reported it."""

    answer: ToolAnswer
    prompt_tokens: int
    completion_tokens: int
    #: the prompt tokens the server found in its prefix cache (``usage.prompt_tokens_details.cached_tokens``)
    cached_tokens: int = 0


def request_body(
    model: str,
    messages: Sequence[Mapping[str, Any]],
    metadata: Mapping[str, Any] | None,
    optional_params: Mapping[str, Any] | None,
) -> dict[str, Any]:
    """The chat request the served copy gets: the call's messages, tools and stop list, and the
    offline hints under their one key."""
    body: dict[str, Any] = {
        "model": f"offline/{model}",
        "messages": [{"role": str(m["role"]), "content": str(m.get("content") or "")} for m in messages],
        OFFLINE_METADATA_KEY: dict((metadata or {}).get(OFFLINE_METADATA_KEY) or {}),
    }
    for key in ("tools", "stop", "max_tokens", "temperature"):
        if (optional_params or {}).get(key) is not None:
            body[key] = optional_params[key]  # type: ignore[index]
    return body


def parse_answer(data: Mapping[str, Any]) -> RemoteAnswer:
    """The reply, tool calls and usage of an OpenAI chat-completion answer."""
    try:
        choice = data["choices"][0]
        message = choice["message"]
        calls = tuple(
            {"id": str(c["id"]), "name": str(c["function"]["name"]), "arguments": str(c["function"]["arguments"])}
            for c in message.get("tool_calls") or ()
        )
        usage = data.get("usage") or {}
        details = usage.get("prompt_tokens_details") or {}
        return RemoteAnswer(
            ToolAnswer(str(message.get("content") or ""), calls),
            int(usage.get("prompt_tokens", 0)),
            int(usage.get("completion_tokens", 0)),
            int(details.get("cached_tokens") or 0),
        )
    except (KeyError, IndexError, TypeError, ValueError) as exc:
        raise RemoteError(502, f"the served test double answered an unreadable body ({type(exc).__name__})") from None


async def forward(api_base: str, body: Mapping[str, Any], timeout_s: float | None) -> RemoteAnswer:
    """POST ``body`` to ``api_base``/chat/completions and read the answer."""
    import aiohttp  # lazy: only a served test double needs it

    url = api_base.rstrip("/") + "/chat/completions"
    try:
        async with aiohttp.ClientSession(timeout=aiohttp.ClientTimeout(total=timeout_s or None)) as session:
            async with session.post(url, json=dict(body)) as resp:
                text = await resp.text()
                if resp.status != 200:
                    raise RemoteError(resp.status, f"the served test double answered HTTP {resp.status}: {text[:300]}")
                try:
                    import json

                    data = json.loads(text)
                except ValueError:
                    raise RemoteError(502, "the served test double answered a body that is not JSON") from None
    except aiohttp.ClientError as exc:
        raise RemoteError(503, f"the served test double is not reachable: {type(exc).__name__}: {exc}") from None
    return parse_answer(data)
