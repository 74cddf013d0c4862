"""TEST DOUBLE: the prompt-caching rules of three providers, as a deterministic simulation.

Why: ReCAP re-sends a long pinned prefix on every call, so what a run costs depends on how the
provider caches prompts. The fake server (:mod:`workers.llm.offline.fake_server`) reports usage by
these rules, in each provider's own usage fields, so litellm parses it as it would the real
answer; ``bench/cost.py`` prices whole trajectories with the same code.

Granularity: a prompt is a sequence of messages and a prefix is identified by a hash chain
over whole messages (role + text). A provider matches tokens, so a real hit can be longer by
part of the first differing message; the double never reports more than a provider would.
Token counts use the documented estimate of :mod:`workers.llm.tokens`: a prefix of ``k`` whole
messages counts ``sum(3 + ceil(chars / 4))`` over them (the prompt adds 3 reply-priming tokens).

Rules (``RULES``):

``openai`` - automatic prefix caching. Source: platform.openai.com/docs/guides/prompt-caching.
  No markers; prompts of at least 1024 tokens are cached; a hit is the longest prefix shared
  with an earlier prompt, reported as 1024 tokens plus whole 128-token increments
  (``cached = 1024 + 128 * floor((prefix - 1024) / 128)``, 0 below 1024); cached prefixes stay
  "5 to 10 minutes of inactivity" (TTL 600 s here, refreshed on every use). Usage:
  ``usage.prompt_tokens_details.cached_tokens``; cache writes are free.

``anthropic`` - explicit breakpoints. Source: docs.anthropic.com/en/docs/build-with-claude/
  prompt-caching. Only prefixes ending at a content block marked ``cache_control:
  {"type": "ephemeral"}`` (at most 4 per request) are written; a prefix shorter than the
  model's minimum (1024 tokens for Sonnet/Opus) is not cached. A request reads the longest
  cached prefix ending at a block boundary at most 20 blocks before one of its breakpoints
  (the documented lookback), and writes everything from there to its last cacheable breakpoint.
  TTL 5 minutes, refreshed on every read. Writes cost 1.25x the input price, reads 0.1x.
  Usage (as litellm parses it from an OpenAI-compatible answer): ``cache_read_input_tokens``
  and ``cache_creation_input_tokens`` next to ``prompt_tokens`` (all input tokens, read and
  written ones included); litellm maps them to ``prompt_tokens_details.cached_tokens`` and
  ``prompt_tokens_details.cache_write_tokens``.

``deepseek`` - automatic cache "prefix units". Source: api-docs.deepseek.com/guides/kv_cache.
  Each request persists two units, at the end of its input and at the end of its output (the
  prompt followed by the reply as an assistant message); when a request shares a prefix with
  an earlier one, that common prefix is persisted as a unit too (usable from the next request
  on). A request hits the longest unit it matches completely. Unused units are cleared "within
  a few hours to a few days" (TTL 4 h here). Usage: ``prompt_cache_hit_tokens`` and
  ``prompt_cache_miss_tokens`` (their sum is ``prompt_tokens``); litellm maps the hits to
  ``prompt_tokens_details.cached_tokens``. Writes are free.

``lcp`` - the fake server's original rule (longest common character prefix with any earlier
  prompt, chars / 4, no minimum), kept for the tests written against it. ``none`` - no cache.

Every rule keeps entries per model; an entry expires ``ttl_s`` after its last use (idle
episodes lose their cache) and the least recently used entries go beyond ``max_entries``.
"""

from __future__ import annotations

import hashlib
import math
from collections import OrderedDict, deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from workers.llm.tokens import REPLY_PRIMING_TOKENS, TOKENS_PER_MESSAGE, estimate_text_tokens

RULES = ("openai", "anthropic", "deepseek", "lcp", "none")
#: seconds an unused entry lives, per rule (see the module doc for the sources)
DEFAULT_TTL_S = {"openai": 600.0, "anthropic": 300.0, "deepseek": 4 * 3600.0, "lcp": math.inf, "none": 0.0}
OPENAI_MIN_TOKENS = 1024
OPENAI_INCREMENT = 128
ANTHROPIC_MIN_TOKENS = 1024
ANTHROPIC_LOOKBACK_BLOCKS = 20
ANTHROPIC_MAX_BREAKPOINTS = 4


@dataclass(frozen=True)
class Message:
    """One prompt message as the cache sees it: its text and whether a breakpoint ends it."""

    role: str
    text: str
    breakpoint: bool = False


@dataclass(frozen=True)
class CacheOutcome:
    """What the simulated provider cache reports for one prompt: its tokens, those read from the
    cache and those written to it."""

    prompt_tokens: int
    cached_tokens: int = 0  # read from the cache
    cache_write_tokens: int = 0  # written to the cache (billed only where writes are priced)


def normalize(messages: Sequence[Mapping[str, Any]]) -> list[Message]:
    """Chat messages (string content, or a list of content blocks) as :class:`Message` items;
    a message carries a breakpoint when it or one of its blocks has ``cache_control``."""
    out = []
    for m in messages:
        content = m.get("content")
        mark = m.get("cache_control") is not None
        if isinstance(content, list):
            parts = []
            for block in content:
                if isinstance(block, Mapping):
                    parts.append(str(block.get("text", "")))
                    mark = mark or block.get("cache_control") is not None
                else:
                    parts.append(str(block))
            text = "".join(parts)
        else:
            text = "" if content is None else str(content)
        out.append(Message(str(m.get("role", "")), text, mark))
    return out


def message_tokens(m: Message) -> int:
    """One message's tokens by the documented estimate: 3 + ceil(characters / 4)."""
    return TOKENS_PER_MESSAGE + estimate_text_tokens(m.text)


def prompt_tokens_of(messages: Sequence[Message]) -> int:
    """The prompt's tokens, as :func:`workers.llm.tokens.estimate_prompt_tokens` counts them."""
    return REPLY_PRIMING_TOKENS + sum(message_tokens(m) for m in messages)


def _chain(messages: Sequence[Message]) -> tuple[list[str], list[int]]:
    """(hash of the first k+1 messages, tokens of the first k+1 messages) for every k."""
    hashes, tokens = [], []
    h = hashlib.sha256(b"prefix")
    total = 0
    for m in messages:
        h = h.copy()
        h.update(len(m.role).to_bytes(4, "big") + m.role.encode() + len(m.text).to_bytes(8, "big") + m.text.encode())
        hashes.append(h.hexdigest())
        total += message_tokens(m)
        tokens.append(total)
    return hashes, tokens


def openai_cached(prefix_tokens: int) -> int:
    """What OpenAI reports cached for a shared prefix of ``prefix_tokens`` tokens."""
    if prefix_tokens < OPENAI_MIN_TOKENS:
        return 0
    return OPENAI_MIN_TOKENS + OPENAI_INCREMENT * ((prefix_tokens - OPENAI_MIN_TOKENS) // OPENAI_INCREMENT)


class _Entries:
    """Prefix hashes of one model with their last use: TTL expiry and LRU eviction."""

    def __init__(self, ttl_s: float, max_entries: int):
        self.ttl_s = ttl_s
        self.max_entries = max_entries
        self._last: OrderedDict[str, float] = OrderedDict()

    def alive(self, key: str, now: float) -> bool:
        t = self._last.get(key)
        if t is None:
            return False
        if now - t > self.ttl_s:
            del self._last[key]
            return False
        return True

    def touch(self, key: str, now: float) -> None:
        self._last[key] = now
        self._last.move_to_end(key)
        while len(self._last) > self.max_entries:
            self._last.popitem(last=False)

    def __len__(self) -> int:
        return len(self._last)


class PromptCache:
    """One provider's prompt cache (see the module doc for the rules)."""

    def __init__(
        self,
        rule: str = "openai",
        *,
        ttl_s: float | None = None,
        max_entries: int = 100_000,
        min_tokens: int | None = None,
        recent_prompts: int = 64,
    ):
        if rule not in RULES:
            raise ValueError(f"unknown cache rule {rule!r}; known: {', '.join(RULES)}")
        self.rule = rule
        self.ttl_s = DEFAULT_TTL_S[rule] if ttl_s is None else float(ttl_s)
        self.max_entries = max_entries
        self.min_tokens = (
            min_tokens
            if min_tokens is not None
            else (ANTHROPIC_MIN_TOKENS if rule == "anthropic" else OPENAI_MIN_TOKENS if rule == "openai" else 0)
        )
        self._entries: dict[str, _Entries] = {}
        #: deepseek: the hash chains of recent prompts (to detect common prefixes); lcp: flat texts
        self._recent: dict[str, deque] = {}
        self._recent_n = recent_prompts

    def _store(self, model: str) -> _Entries:
        if model not in self._entries:
            self._entries[model] = _Entries(self.ttl_s, self.max_entries)
        return self._entries[model]

    def clear(self) -> None:
        self._entries.clear()
        self._recent.clear()

    def entries(self, model: str) -> int:
        return len(self._entries.get(model, ()))

    def serve(self, model: str, messages: Sequence[Message], now: float, reply: str | None = None) -> CacheOutcome:
        """Tokens read from and written to the cache by one request (which updates the cache)."""
        prompt = prompt_tokens_of(messages)
        if self.rule == "none":
            return CacheOutcome(prompt)
        if self.rule == "lcp":
            return CacheOutcome(prompt, min(prompt, self._lcp(model, messages) // 4))
        hashes, tokens = _chain(messages)
        store = self._store(model)
        if self.rule == "openai":
            return self._openai(store, hashes, tokens, prompt, now)
        if self.rule == "anthropic":
            return self._anthropic(store, messages, hashes, tokens, prompt, now)
        return self._deepseek(model, store, messages, hashes, tokens, prompt, now, reply)

    # ---- rules ----
    def _openai(self, store: _Entries, hashes: list[str], tokens: list[int], prompt: int, now: float) -> CacheOutcome:
        hit = 0
        for k in range(len(hashes) - 1, -1, -1):
            if store.alive(hashes[k], now):
                hit = tokens[k]
                break
        if prompt >= self.min_tokens:  # this prompt's prefixes become cached (and refreshed)
            for h in hashes:
                store.touch(h, now)
        return CacheOutcome(prompt, min(openai_cached(hit), prompt))

    def _anthropic(
        self, store: _Entries, messages: Sequence[Message], hashes: list[str], tokens: list[int], prompt: int, now: float
    ) -> CacheOutcome:
        breaks = [i for i, m in enumerate(messages) if m.breakpoint][:ANTHROPIC_MAX_BREAKPOINTS]
        if not breaks:
            return CacheOutcome(prompt)
        read_at = -1  # index of the last message of the longest cached prefix found
        for bp in sorted(breaks, reverse=True):
            for k in range(bp, max(-1, bp - ANTHROPIC_LOOKBACK_BLOCKS - 1), -1):
                if k > read_at and store.alive(hashes[k], now):
                    read_at = k
                    break
        read = tokens[read_at] if read_at >= 0 else 0
        if read_at >= 0:
            store.touch(hashes[read_at], now)  # a read refreshes the entry's TTL
        written_to = read_at
        for bp in breaks:
            if tokens[bp] >= self.min_tokens and bp > read_at:
                store.touch(hashes[bp], now)
                written_to = max(written_to, bp)
        write = tokens[written_to] - read if written_to > read_at else 0
        return CacheOutcome(prompt, read, write)

    def _deepseek(
        self,
        model: str,
        store: _Entries,
        messages: Sequence[Message],
        hashes: list[str],
        tokens: list[int],
        prompt: int,
        now: float,
        reply: str | None,
    ) -> CacheOutcome:
        hit = 0
        for k in range(len(hashes) - 1, -1, -1):
            if store.alive(hashes[k], now):
                hit = tokens[k]
                store.touch(hashes[k], now)
                break
        recent = self._recent.setdefault(model, deque(maxlen=self._recent_n))
        common = -1  # the longest prefix shared with a recent request becomes a unit
        for earlier in recent:
            k = 0
            while k < min(len(earlier), len(hashes)) and earlier[k] == hashes[k]:
                k += 1
            common = max(common, k - 1)
        if common >= 0:
            store.touch(hashes[common], now)
        recent.append(hashes)
        if hashes:
            store.touch(hashes[-1], now)  # the end of the input
            if reply is not None:  # the end of the output: the prompt + the reply
                out, _ = _chain([*messages, Message("assistant", reply)])
                store.touch(out[-1], now)
        return CacheOutcome(prompt, min(hit, prompt))

    def _lcp(self, model: str, messages: Sequence[Message]) -> int:
        flat = "".join(f"{m.role}:{m.text}\n" for m in messages)
        recent = self._recent.setdefault(model, deque(maxlen=self._recent_n))
        best = max((_common_chars(flat, p) for p in recent), default=0)
        recent.append(flat)
        return best


def _common_chars(a: str, b: str) -> int:
    """Length of the longest common prefix (binary search on C-level slice compares)."""
    lo, hi = 0, min(len(a), len(b))
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if a[:mid] == b[:mid]:
            lo = mid
        else:
            hi = mid - 1
    return lo


def usage_fields(rule: str, prompt_tokens: int, cached: Any, written: Any) -> dict[str, Any]:
    """The usage fields one rule's provider reports its cache in (None values are left out)."""
    if rule == "anthropic":
        out = {"cache_read_input_tokens": cached, "cache_creation_input_tokens": written}
    elif rule == "deepseek":
        miss = prompt_tokens - cached if isinstance(prompt_tokens, int) and isinstance(cached, int) else None
        out = {"prompt_cache_hit_tokens": cached, "prompt_cache_miss_tokens": miss}
    else:
        return {} if cached is None else {"prompt_tokens_details": {"cached_tokens": cached}}
    return {k: v for k, v in out.items() if v is not None}
