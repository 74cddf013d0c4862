"""Cache breakpoints for providers that cache only where the request says so (Anthropic).

Why here and not in the agent: where a prompt stays stable is a fact of the traffic, so the
gateway can see it without the agent knowing anything about providers. The agent's messages
are pins (demonstration, task) followed by a window; under ``pair`` trimming the window
shifts on nearly every call, under ``block`` trimming it only grows between trims. So the
part of a request that repeats an earlier request of the same episode is exactly:

* the pinned prefix, under ``pair`` trimming (the window behind it has shifted), and
* the pins plus the stable block, under ``block`` trimming (everything the previous call sent).

:class:`BreakpointPlanner` marks the end of the longest and of the shortest prefix the request
shares with the episode's last few requests (at most two of Anthropic's four breakpoints): the
first makes the next call read everything that has repeated, the second keeps the pinned
prefix cached across a trim, when the window's start changes. A prefix is marked only once
it has been sent twice, because a write costs 1.25x the input price and only a prefix that
comes back pays that back: the window of ``pair`` trimming, which never comes back, is never
written. The first request of an episode carries no marker.

Markers travel in litellm's supported message format: the message's content becomes a list
with one text block carrying ``cache_control: {"type": "ephemeral"}``, which litellm passes to
Anthropic as is (and to an OpenAI-compatible server unchanged). Token counts, fingerprints
and records are computed on the plain messages, before marking.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict, deque
from collections.abc import Sequence
from typing import Any

EPHEMERAL = {"type": "ephemeral"}
#: requests remembered per episode, and episodes remembered per gateway
RECENT_REQUESTS = 4
EPISODES = 4096


def _digest(message: dict[str, Any]) -> str:
    role, content = str(message.get("role", "")), str(message.get("content", ""))
    return hashlib.sha256(f"{len(role)}:{role}:{content}".encode()).hexdigest()


def _shared(a: Sequence[str], b: Sequence[str]) -> int:
    n = 0
    for x, y in zip(a, b):
        if x != y:
            break
        n += 1
    return n


class BreakpointPlanner:
    """Remembers each episode's recent requests and says where the next one should be marked."""

    def __init__(self, recent: int = RECENT_REQUESTS, episodes: int = EPISODES):
        self._recent = recent
        self._episodes = episodes
        self._seen: OrderedDict[str, deque[tuple[str, ...]]] = OrderedDict()

    def plan(self, episode_id: str, messages: Sequence[dict[str, Any]]) -> tuple[int, ...]:
        """Indexes of the messages that end a marked prefix (ascending; empty: mark nothing).
        Records the request as the episode's latest."""
        digests = tuple(_digest(m) for m in messages)
        history = self._seen.get(episode_id)
        marks: tuple[int, ...] = ()
        if history:
            shared = [n for n in (_shared(d, digests) for d in history) if n > 0]
            if shared:
                marks = tuple(sorted({min(shared) - 1, max(shared) - 1}))
        if history is None:
            history = self._seen[episode_id] = deque(maxlen=self._recent)
        self._seen.move_to_end(episode_id)
        history.append(digests)
        while len(self._seen) > self._episodes:
            self._seen.popitem(last=False)
        return marks

    def forget(self, episode_id: str) -> None:
        self._seen.pop(episode_id, None)


def with_markers(messages: Sequence[dict[str, Any]], marks: Sequence[int]) -> list[dict[str, Any]]:
    """The messages with a ``cache_control`` text block on each index in ``marks``."""
    out = [dict(m) for m in messages]
    for i in marks:
        m = out[i]
        m["content"] = [{"type": "text", "text": str(m.get("content", "")), "cache_control": dict(EPHEMERAL)}]
    return out


def mark(planner: BreakpointPlanner, episode_id: str, messages: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """``messages`` as sent to a provider with explicit caching (see the module doc)."""
    return with_markers(messages, planner.plan(episode_id, messages))
