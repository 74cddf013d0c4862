"""Offline prompt-token counts: a tokenizer where one ships with the install, else an estimate.

Why: admission control (TPM) and the budget reservation must know a request's size *before*
it is sent, and nothing may be downloaded at run time. litellm bundles three tiktoken
encodings (cl100k_base, o200k_base, p50k_base); OpenAI models that map to one of them are
counted exactly ("tokenizer"). Every other model (Llama, Qwen, DeepSeek, self-hosted) gets the
documented estimate ``ceil(chars / 4)`` per message ("estimate"); the provider's reported
usage replaces either count after the call ("provider").

Two numbers are used:
- :func:`count_prompt_tokens` - the best guess, for TPM windows and for the record when the
  provider reports no usage;
- :func:`prompt_token_bound` - an upper bound, for the budget reservation, so a cap is never
  exceeded even when the estimate is low: byte-level BPE and SentencePiece-with-byte-fallback
  tokenizers emit at most one token per UTF-8 byte, plus chat-template tokens per message.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import threading
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

from workers.llm.litellm_import import import_litellm

#: chars per token of the estimate (English text with GPT-style BPE is about 4)
CHARS_PER_TOKEN = 4
#: tokens the OpenAI chat format adds per message (role + separators) and to prime the reply
TOKENS_PER_MESSAGE = 3
REPLY_PRIMING_TOKENS = 3
#: chat-template tokens allowed per message / per request in the upper bound (any template
#: we know of uses fewer: Llama-3 uses 5 per message, ChatML 4-5)
BOUND_TOKENS_PER_MESSAGE = 16
BOUND_TOKENS_PER_REQUEST = 32

_ENCODING_URL = "https://openaipublic.blob.core.windows.net/encodings/{}.tiktoken"
#: provider prefixes whose model names are OpenAI model names
_OPENAI_PREFIXES = ("openai/", "azure/", "text-completion-openai/")


@dataclass(frozen=True)
class TokenCount:
    """A token count and how it was made: ``tokenizer`` (the model's own tokenizer) or ``estimate``
    (characters / 4)."""

    tokens: int
    source: str  # "tokenizer" | "estimate"


#: what a tool definition costs beside its JSON in our count (the provider's framing of it)
TOKENS_PER_TOOL = 8
#: the same, in the upper bound: a provider's rendering of one tool (name, description, a
#: namespace line) never adds more than this beyond its JSON's bytes
BOUND_TOKENS_PER_TOOL = 64


def estimate_text_tokens(text: str) -> int:
    """The documented estimate: ceil(characters / 4)."""
    return math.ceil(len(text) / CHARS_PER_TOKEN)


def _content(message: Mapping[str, Any]) -> str:
    """The text of a message a provider bills: its content, and an assistant's tool calls (each
    call's id, name and arguments) or a tool result's call id."""
    content = message.get("content") or ""
    text = content if isinstance(content, str) else str(content)
    calls = message.get("tool_calls") or ()
    parts = [text]
    for call in calls:
        if not isinstance(call, Mapping):
            continue
        fn = call.get("function") or {}
        parts += [str(call.get("id", "")), str(fn.get("name", "")), str(fn.get("arguments", ""))]
    if message.get("tool_call_id"):
        parts.append(str(message["tool_call_id"]))
    return "\n".join(p for p in parts if p)


def tools_text(tools: Sequence[Mapping[str, Any]] | None) -> str:
    """The tool definitions of a request as the text we count (their JSON); providers render them
    into the prompt in their own form, which the per-tool allowance covers."""
    return json.dumps(list(tools), sort_keys=True, ensure_ascii=False) if tools else ""


def estimate_prompt_tokens(messages: Sequence[Mapping[str, Any]], tools: Sequence[Mapping[str, Any]] | None = None) -> int:
    """Estimate of a chat prompt: per message ceil(chars/4) + 3, plus 3 for the reply, plus the
    tool definitions' JSON at ceil(chars/4) and :data:`TOKENS_PER_TOOL` each."""
    n = REPLY_PRIMING_TOKENS + sum(TOKENS_PER_MESSAGE + estimate_text_tokens(_content(m)) for m in messages)
    if tools:
        n += estimate_text_tokens(tools_text(tools)) + TOKENS_PER_TOOL * len(tools)
    return n


def _bundled_encoding_available(name: str) -> bool:
    """True when tiktoken can load ``name`` from the local cache (litellm's bundled files)."""
    cache_dir = os.environ.get("TIKTOKEN_CACHE_DIR")
    if not cache_dir:
        return False
    key = hashlib.sha1(_ENCODING_URL.format(name).encode()).hexdigest()
    return os.path.exists(os.path.join(cache_dir, key))


@lru_cache(maxsize=64)
def _encoding_for(model: str) -> Any:
    """The tiktoken encoding of an OpenAI model name, or None (not OpenAI / not bundled)."""
    import_litellm()  # sets TIKTOKEN_CACHE_DIR to the bundled encodings
    base = model
    for prefix in _OPENAI_PREFIXES:
        if base.startswith(prefix):
            base = base[len(prefix) :]
            break
    else:
        if "/" in base:  # another provider's model: no bundled tokenizer
            return None
    # tiktoken only here: it comes with litellm, which must be imported (offline) first
    import tiktoken
    import tiktoken.model

    try:
        name = tiktoken.model.encoding_name_for_model(base)
    except KeyError:
        return None
    if not _bundled_encoding_available(name):
        return None
    return tiktoken.get_encoding(name)


class EncodedLengths:
    """Token counts of texts under one encoding, remembered by content digest (a bounded LRU).

    Why: agents re-send their conversation on every call (ReCAP re-sends long prefixes), so
    without memory a call's count encodes every earlier message again and an episode's counting
    grows with the square of its length. A message is counted once; later calls look its
    count up by a 128-bit BLAKE2 digest of its text (no text is kept). Texts shorter than
    :attr:`min_chars` are encoded directly (cheaper than the digest)."""

    def __init__(self, encoding: Any, *, max_entries: int = 8192, min_chars: int = 256):
        self.encoding = encoding
        self.max_entries = max_entries
        self.min_chars = min_chars
        self._counts: OrderedDict[bytes, int] = OrderedDict()
        self._lock = threading.Lock()  # the direct client may count from several threads
        self.hits = 0

    def __call__(self, text: str) -> int:
        if len(text) < self.min_chars:
            return len(self.encoding.encode(text, disallowed_special=()))
        key = hashlib.blake2b(text.encode("utf-8", "surrogatepass"), digest_size=16).digest()
        with self._lock:
            n = self._counts.get(key)
            if n is not None:
                self._counts.move_to_end(key)
                self.hits += 1
                return n
        n = len(self.encoding.encode(text, disallowed_special=()))
        with self._lock:
            self._counts[key] = n
            if len(self._counts) > self.max_entries:
                self._counts.popitem(last=False)
        return n


@lru_cache(maxsize=64)
def _lengths_for(model: str) -> EncodedLengths | None:
    """The memoised counter of a model's encoding (one per encoding object), or None."""
    enc = _encoding_for(model)
    return None if enc is None else _lengths_of(enc)


@lru_cache(maxsize=8)
def _lengths_of(enc: Any) -> EncodedLengths:
    return EncodedLengths(enc)


def count_prompt_tokens(
    model: str, messages: Sequence[Mapping[str, Any]], tools: Sequence[Mapping[str, Any]] | None = None
) -> TokenCount:
    """Prompt tokens of a chat request (its messages and tool definitions), counted offline
    (each message's text through :class:`EncodedLengths`: the same count, once per text)."""
    lengths = _lengths_for(model)
    if lengths is None:
        return TokenCount(estimate_prompt_tokens(messages, tools), "estimate")
    n = REPLY_PRIMING_TOKENS
    for m in messages:
        n += TOKENS_PER_MESSAGE + lengths(_content(m))
        n += lengths(str(m.get("role", "")))
    if tools:
        n += lengths(tools_text(tools)) + TOKENS_PER_TOOL * len(tools)
    return TokenCount(n, "tokenizer")


def count_text_tokens(model: str, text: str) -> TokenCount:
    """Tokens of a completion text (used only when the provider reports no usage)."""
    enc = _encoding_for(model)
    if enc is None:
        return TokenCount(estimate_text_tokens(text), "estimate")
    return TokenCount(len(enc.encode(text, disallowed_special=())), "tokenizer")


def prompt_token_bound(
    model: str,
    messages: Sequence[Mapping[str, Any]],
    counted: TokenCount | None = None,
    tools: Sequence[Mapping[str, Any]] | None = None,
) -> int:
    """An upper bound on the prompt tokens any provider will bill for these messages and tool
    definitions (a provider renders the tools into the prompt in its own words: at most one token
    per byte of their JSON plus :data:`BOUND_TOKENS_PER_TOOL` each)."""
    counted = counted or count_prompt_tokens(model, messages, tools)
    tool_slack = BOUND_TOKENS_PER_TOOL * len(tools or ())
    if counted.source == "tokenizer":
        return counted.tokens + BOUND_TOKENS_PER_REQUEST + tool_slack
    bound = BOUND_TOKENS_PER_REQUEST + sum(BOUND_TOKENS_PER_MESSAGE + len(_content(m).encode("utf-8")) for m in messages)
    return bound + len(tools_text(tools).encode("utf-8")) + tool_slack
