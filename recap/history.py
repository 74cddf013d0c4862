"""The one shared LLM message history of an episode, with pins and a bounded sliding window.

Two messages are pinned (the one-shot demonstration and the initial task prompt); every other
message lives in a window of at most ``K`` messages that is enforced on *every* insertion, so a
call never sees more than ``K + pins`` messages (the authors' code trims once per call and lets
inserted messages creep past the bound).

Two trimming modes keep the same bound:

* ``pair``: drop the oldest (assistant, user) pair whenever the window overflows — the paper's
  rule; the prompt prefix changes on nearly every call.
* ``block``: when the window overflows, drop a block of the oldest messages at once (default
  K/2). Consecutive prompts then share a long identical prefix for K/2 insertions, which lets
  providers' prompt caching bill that prefix at the cached-input price.

Messages are dropped in pairs so the window always continues the user/assistant alternation
that starts after the pinned task prompt. Tool messages (the results of a reply's tool calls)
are dropped with the reply that called them: a window never starts with a tool result whose
call it no longer holds.

* ``prompt``: the released FEVER ReCAP's cut (fever-recap/MATRIX/MATRIX/chatbot.py:42-45): only
  when a prompt goes in (a user message other than a repair message), and only if the history then
  holds more than K messages, exactly the two oldest unpinned messages go first; nothing else
  trims, so a call may see K + 1 messages after an odd message (the error message after a reply
  that is not JSON, chatbot.py:464-466) as it does there.

``counts_pins`` makes K bound the whole history, pins included (the released code's reading:
"more than ctx_len messages" counts the demonstration and the task prompt); otherwise K bounds
the messages after the pins.

``keep`` windowed messages at the head of the window are never dropped, though they count
towards K: the released Robotouille ReAct trims its history with ``del history[2:4]``
(robotouille-baselines/agents/ReAct_agent.py:129-130, 138), and its history starts with the first
observation and the first reply, so that reply stays for the whole episode (our pin already
holds the first observation, so ``keep=1``).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

from recap.llm import ChatMessage, ToolCall
from recap.row_bounds import MAX_ARGUMENTS_CHARS, MAX_NAME_CHARS, cut
from schemas.records import MessageRecord

WindowMode = Literal["pair", "block", "prompt"]


class SeqCounter:
    """Message numbers of one episode, shared by all of its histories."""

    def __init__(self) -> None:
        self.value = 0

    def take(self) -> int:
        self.value += 1
        return self.value - 1


@dataclass(frozen=True)
class Entry:
    """One message of a :class:`History`: its episode-wide ``seq``, the message, the template it
    came from (``kind``), the tree node it belongs to (None: none) and whether it is pinned."""

    seq: int
    message: ChatMessage
    kind: str
    node_id: int | None
    pinned: bool


class History:
    """One context's message history: pins that are never trimmed plus a window of at most
    ``window`` messages, enforced on every insertion (see the module docstring); every message added
    is emitted as a ``messages`` row. Raises ValueError for a window below 2 or an unknown mode."""

    def __init__(
        self,
        episode_id: str,
        window: int,
        *,
        mode: WindowMode = "pair",
        block: int | None = None,
        emit: Callable[[MessageRecord], None] | None = None,
        counter: SeqCounter | None = None,
        counts_pins: bool = False,
        keep: int = 0,
    ) -> None:
        if window < 2:
            raise ValueError(f"window must be at least 2 messages, got {window}")
        if mode not in ("pair", "block", "prompt"):
            raise ValueError(f"window mode must be 'pair', 'block' or 'prompt', got {mode!r}")
        self.episode_id = episode_id
        self.window = window
        self.mode = mode
        blk = block if block is not None else max(2, window // 2)
        self.block = max(2, min(window, blk + (blk % 2)))
        self._emit = emit or (lambda _r: None)
        self._pins: list[Entry] = []
        self._live: list[Entry] = []
        # a counter shared by every history of an episode keeps message seqs unique when an agent
        # (ADaPT) works with several separate contexts
        self._counter = counter if counter is not None else SeqCounter()
        self.dropped = 0
        self.counts_pins = counts_pins
        if keep < 0 or keep >= window:
            raise ValueError(f"keep must be in [0, window), got {keep}")
        self.keep = keep

    @property
    def live_limit(self) -> int:
        """How many unpinned messages the window holds."""
        if self.counts_pins:
            return max(2, self.window - len(self._pins))
        return self.window

    # -- insertion -----------------------------------------------------------------------
    def pin(self, role: str, kind: str, content: str) -> int:
        """Add a message that is never trimmed (demonstration, initial task prompt)."""
        if self._live:
            raise RuntimeError("pins must be added before any windowed message")
        return self._insert(ChatMessage(role, content), kind, None, pinned=True)

    def add(
        self,
        role: str,
        kind: str,
        content: str,
        node_id: int | None = None,
        *,
        tool_calls: tuple[ToolCall, ...] = (),
        tool_call_id: str | None = None,
    ) -> int:
        """Add a windowed message (an assistant reply may carry ``tool_calls``; a ``tool``
        message answers one of them by ``tool_call_id``) and enforce the window."""
        message = ChatMessage(role, content, tool_calls=tool_calls, tool_call_id=tool_call_id)
        if self.mode == "prompt":
            if role == "user" and kind != "repair" and (len(self) if self.counts_pins else len(self._live)) > self.window:
                n = min(2, max(0, len(self._live) - self.keep))
                del self._live[self.keep : self.keep + n]  # chatbot.py:42-44: del history[1:3]
                self.dropped += n
            return self._insert(message, kind, node_id, pinned=False)
        seq = self._insert(message, kind, node_id, pinned=False)
        # the results of a reply's tool calls follow it at once: the window is enforced once the
        # last of them is in, never between a call and its result (see drop_oldest)
        if role != "assistant" or not tool_calls:
            self._enforce()
        return seq

    def _insert(self, message: ChatMessage, kind: str, node_id: int | None, pinned: bool) -> int:
        seq = self._counter.take()
        (self._pins if pinned else self._live).append(Entry(seq, message, kind, node_id, pinned))
        calls = message.tool_calls
        self._emit(
            MessageRecord(
                episode_id=self.episode_id,
                seq=seq,
                role=message.role,
                kind=kind,
                content=message.content,
                node_id=node_id,
                pinned=pinned,
                tool_call_id=None if message.tool_call_id is None else cut(message.tool_call_id, MAX_NAME_CHARS),
                tool_calls=json.dumps([_bounded(c) for c in calls]) if calls else None,
            )
        )
        return seq

    def _enforce(self) -> None:
        limit = self.live_limit
        if len(self._live) <= limit:
            return
        if self.mode == "pair":
            excess = len(self._live) - limit
            self.drop_oldest(excess + (excess % 2))
        else:
            while len(self._live) > limit:
                self.drop_oldest(min(self.block, limit))

    # -- trimming ------------------------------------------------------------------------
    def drop_oldest(self, n: int) -> int:
        """Drop up to ``n`` (rounded up to even) of the oldest unpinned messages after the
        ``keep`` kept ones, never the newest one. Returns how many were dropped."""
        n += n % 2
        n = min(n, max(0, len(self._live) - 1 - self.keep))
        if self.keep:
            n -= n % 2  # whole (prompt, reply) pairs after a kept reply keep the alternation
        if n <= 0:
            return 0
        # a tool result never outlives the reply that called it: results left at the head of
        # the window go with their call (a provider refuses a tool message without its call)
        while self.keep + n < len(self._live) - 1 and self._live[self.keep + n].message.role == "tool":
            n += 1
        del self._live[self.keep : self.keep + n]
        self.dropped += n
        return n

    def forget(self, seq: int) -> None:
        """Remove the unpinned message ``seq`` from the context (its row was emitted when it was
        added); KeyError when the window holds no such message."""
        for n, entry in enumerate(self._live):
            if entry.seq == seq:
                del self._live[n]
                return
        raise KeyError(f"no unpinned message {seq} in the context")

    # -- reading -------------------------------------------------------------------------
    @property
    def next_seq(self) -> int:
        """The seq the next inserted message of this history will get."""
        return self._counter.value

    @property
    def counter(self) -> SeqCounter:
        return self._counter

    def entries(self) -> list[Entry]:
        return [*self._pins, *self._live]

    def messages(self) -> tuple[ChatMessage, ...]:
        return tuple(e.message for e in self.entries())

    def seqs(self) -> tuple[int, ...]:
        return tuple(e.seq for e in self.entries())

    def __len__(self) -> int:
        return len(self._pins) + len(self._live)

    @property
    def live_count(self) -> int:
        return len(self._live)


def _bounded(call: ToolCall) -> dict[str, str]:
    """A call as the ``messages`` row keeps it: each field cut to its bound (the history itself
    keeps, and sends, the whole call)."""
    return {
        "id": cut(call.id, MAX_NAME_CHARS),
        "name": cut(call.name, MAX_NAME_CHARS),
        "arguments": cut(call.arguments, MAX_ARGUMENTS_CHARS),
    }
