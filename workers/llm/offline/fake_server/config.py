"""The fake server's settings (quotas, faults, caching) and its log of arrivals."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from workers.llm.offline.fake_server.faults import DEFAULT_REPLY, FAULT_MODES
from workers.llm.prompt_cache import RULES


@dataclass
class FakeServerConfig:
    """The server's quotas, faults and caching rules (see the module docstring for each)."""

    rpm: int | None = None
    tpm: int | None = None
    window_s: float = 60.0
    latency_s: float = 0.0
    latency_jitter_s: float = 0.0
    reply: str = DEFAULT_REPLY
    max_context_tokens: int | None = None
    #: mode -> probability per request (seeded, in arrival order)
    fault_rates: dict[str, float] = field(default_factory=dict)
    seed: int = 0
    hang_s: float = 3600.0
    require_api_key: str | None = None
    #: earlier prompts kept to compute cached tokens (rules lcp and deepseek)
    prefix_memory: int = 64
    #: the prompt-cache rule of models not in ``cache_rules`` (see workers.llm.prompt_cache)
    cache_rule: str = "lcp"
    #: model name (as the request names it) -> cache rule: one rule per deployment
    cache_rules: dict[str, str] = field(default_factory=dict)
    #: seconds an unused cache entry lives (None: the rule's documented default)
    cache_ttl_s: float | None = None
    #: the smallest cacheable prefix (None: the rule's default, 1024 for openai / anthropic)
    cache_min_tokens: int | None = None
    #: keep every request body (``FakeServer.bodies``), for tests of what reaches a provider
    keep_bodies: bool = False
    #: the Retry-After (seconds) of every 429, instead of the time the window needs
    retry_after_s: float | None = None
    #: the Retry-After of the ``retrylong`` mode
    long_retry_after_s: float = 3600.0
    #: fields replacing those of every reply's usage block (prompt_tokens, completion_tokens,
    #: cached_tokens, total_tokens; None leaves the field out)
    usage_override: dict[str, Any] | None = None

    def __post_init__(self) -> None:
        bad = set(self.fault_rates) - set(FAULT_MODES)
        if bad:
            raise ValueError(f"unknown fault mode(s) {sorted(bad)}; known: {', '.join(FAULT_MODES)}")
        for rule in (self.cache_rule, *self.cache_rules.values()):
            if rule not in RULES:
                raise ValueError(f"unknown cache rule {rule!r}; known: {', '.join(RULES)}")

    def rule_for(self, model: str) -> str:
        """The prompt-cache rule of ``model`` (its own, else the default)."""
        return self.cache_rules.get(model, self.cache_rule)


@dataclass(frozen=True)
class FakeCall:
    """One arrival as the server saw it."""

    t: float  # time.monotonic() at arrival
    status: int
    mode: str
    model: str
    prompt_tokens: int
    completion_tokens: int
    cached_tokens: int
    max_tokens: int | None
    #: tokens counted against TPM (0 when the request was refused before counting)
    counted_tokens: int
    #: prompt tokens written to the cache (the anthropic rule; 0 otherwise)
    cache_write_tokens: int = 0


def window_maxima(calls: Sequence[FakeCall], window_s: float) -> tuple[int, int]:
    """The most requests and tokens that any window (t - window_s, t] held, over counted calls."""
    counted = sorted((c for c in calls if c.counted_tokens > 0), key=lambda c: c.t)
    best_n = best_tok = 0
    j = 0
    tokens = 0
    for i, c in enumerate(counted):
        tokens += c.counted_tokens
        while counted[j].t <= c.t - window_s:
            tokens -= counted[j].counted_tokens
            j += 1
        best_n = max(best_n, i - j + 1)
        best_tok = max(best_tok, tokens)
    return best_n, best_tok
