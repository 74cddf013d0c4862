"""Provider exceptions -> the error classes of :data:`recap.llm.ERROR_KINDS`, and secret scrubbing.

Why one place: the gateway, the direct client and the retry policy must agree on what a
failure *is* (retry it? shrink concurrency? give up at once?). litellm maps every provider's
errors onto OpenAI-style exception classes with a ``status_code``; we map those (and plain
asyncio/httpx timeouts) onto our seven kinds. Messages are scrubbed of API keys before they
reach any record, log line or exception, because providers echo keys back in auth errors.
"""

from __future__ import annotations

import asyncio
import email.utils
import json
import logging
import re
import time
from collections.abc import Iterable
from dataclasses import dataclass, replace
from typing import Any

from schemas.kinds import LLMErrorKind
from schemas.outcomes import BudgetRefusal
from workers.llm.litellm_import import import_litellm

#: kinds worth another attempt; the others are returned to the caller at once
RETRYABLE_KINDS = frozenset({"rate_limit", "timeout", "server_error"})
MAX_MESSAGE_CHARS = 500

_SECRET_PATTERNS = (
    re.compile(r"\b(sk|pk|rk)-[A-Za-z0-9_\-*]{6,}"),  # OpenAI/DeepSeek/Anthropic style
    re.compile(r"(?i)((?:bearer|basic)\s+)[A-Za-z0-9._\-~+/=*]{8,}"),
    re.compile(r"(?i)((?:api[_-]?key|authorization|x-api-key|token)[\"']?\s*[:=]\s*[\"']?)[^\s\"',}]{6,}"),
    # credentials inside a URL: scheme://user:password@host, ?key=... / &token=...
    re.compile(r"(?i)\b([a-z][a-z0-9+.\-]*://)[^/\s@]+@"),
    re.compile(r"(?i)([?&](?:key|api[_-]?key|apikey|token|access_token|auth|secret|password|sig|signature|code)=)[^&\s\"'#]+"),
)


def redact_known(text: str, secrets: Iterable[str | None] = ()) -> str:
    """``text`` with each given secret (4+ characters; longest first) replaced by ``[REDACTED]``.

    For model replies: only the deployment's own secrets are removed (an API key or base-URL
    credential the provider echoed), never text that merely looks like a key."""
    out = str(text)
    for secret in sorted({s for s in secrets if s and len(s) >= 4}, key=len, reverse=True):
        out = out.replace(secret, "[REDACTED]")
    return out


def scrub(text: str, secrets: Iterable[str | None] = ()) -> str:
    """``text`` with the given secrets and anything that looks like an API key (or a
    credential inside a URL) replaced."""
    out = redact_known(text, secrets)
    out = _SECRET_PATTERNS[0].sub("[REDACTED]", out)
    out = _SECRET_PATTERNS[1].sub(r"\1[REDACTED]", out)
    out = _SECRET_PATTERNS[2].sub(r"\1[REDACTED]", out)
    out = _SECRET_PATTERNS[3].sub(r"\1[REDACTED]@", out)
    out = _SECRET_PATTERNS[4].sub(r"\1[REDACTED]", out)
    return out


@dataclass(frozen=True)
class Classified:
    """What one failed attempt was: its error kind, a message with API keys scrubbed, and what the
    retry policy and the accounting need (Retry-After, HTTP status, whether it may have been billed,
    the cap that refused it)."""

    kind: LLMErrorKind
    message: str
    #: seconds the provider asked us to wait (Retry-After), if it said
    retry_after_s: float | None = None
    status_code: int | None = None
    #: the provider may have generated (and billed) an answer we could not use: a timeout, or an
    #: HTTP 200 we could not turn into a usable reply (:func:`unreadable_reply`: a body that is not
    #: JSON or cut short, an HTML page, fractional token counts, no choice, a null message).
    #: Such an attempt is charged at its reservation (the worst case), never at zero.
    maybe_billed: bool = False
    #: a ``budget`` refusal: which cap refused the call (the driver stops the run or the model by it)
    refusal: BudgetRefusal | None = None

    @property
    def retryable(self) -> bool:
        return self.kind in RETRYABLE_KINDS


def refused_retry_after(c: Classified, max_retry_after_s: float) -> Classified | None:
    """The call's failure when a 429 asks for a longer wait than ``max_retry_after_s`` (the call
    fails instead of pausing the deployment: nobody waits an hour), else None."""
    if c.kind != "rate_limit" or c.retry_after_s is None or c.retry_after_s <= max_retry_after_s:
        return None
    message = (
        f"provider asked to wait {c.retry_after_s:g}s (Retry-After), more than "
        f"max_retry_after_s={max_retry_after_s:g}: the call fails instead of pausing; " + c.message
    )
    return replace(c, message=message[:500])


def _header(headers: Any, name: str) -> str | None:
    if headers is None:
        return None
    try:
        items = headers.items() if hasattr(headers, "items") else headers
        for k, v in items:
            if str(k).lower() == name:
                return str(v)
    except Exception:
        return None
    return None


def retry_after_seconds(exc: BaseException) -> float | None:
    """Retry-After of a provider error, from litellm's copy of the response headers."""
    sources = [getattr(exc, "litellm_response_headers", None)]
    response = getattr(exc, "response", None)
    if response is not None:
        sources.append(getattr(response, "headers", None))
    for headers in sources:
        ms = _header(headers, "retry-after-ms")
        if ms is not None:
            try:
                return max(0.0, float(ms) / 1000.0)
            except ValueError:
                pass
        s = _header(headers, "retry-after")
        if s is not None:
            try:
                return max(0.0, float(s))
            except ValueError:
                when = _http_date(s)
                if when is not None:
                    return when
    return None


def _http_date(value: str) -> float | None:
    """Seconds from now until an HTTP-date Retry-After (0 when past), None when unparseable."""
    try:
        when = email.utils.parsedate_to_datetime(value.strip())
    except (TypeError, ValueError, IndexError):
        return None
    if when is None:
        return None
    return max(0.0, when.timestamp() - time.time())


_CONTEXT_MARKERS = (
    "context_length_exceeded",
    "maximum context length",
    "context window",
    "too many tokens",
    "prompt is too long",
)


def _kind_of_status(status: int | None, text: str) -> LLMErrorKind | None:
    if status is None:
        return None
    if status == 429:
        return "rate_limit"
    if status in (401, 403):
        return "auth"
    if status in (408, 504):
        return "timeout"
    if status >= 500:
        return "server_error"
    if status == 400 and any(m in text.lower() for m in _CONTEXT_MARKERS):
        return "context_length"
    if 400 <= status < 500:
        return "bad_request"
    return None


#: litellm's words when an HTTP 200 reply could not be turned into a response (it then raises a
#: 500-class error although the provider answered, and may have billed, the request): a body
#: that is not JSON (or cut short), an HTML page, ``choices`` that is not a list, a choice it
#: cannot convert
_UNREADABLE_REPLY_MARKERS = (
    "Invalid response object",
    "convert_to_model_response_object",
    "Empty or invalid response from LLM endpoint",
    "returned 'choices' that is not a list",
    "[200 OK]",
)


class UnusableReply(Exception):
    """An HTTP 200 answer that holds no reply we can use: no choice (``choices`` empty or null), a
    choice without a message, or a message whose content is null with no tool calls (unless its
    finish reason is ``tool_calls``: the model said it called tools and called none, an empty reply
    that is its own, :func:`workers.llm.calling.unusable_reason`).

    Why an exception and not an empty reply: handed on as ``""``, the agent read it as the
    model's own failure (a JSON failure no resume retries), although the provider failed - and
    may have billed the request. The gateway classifies it as a ``server_error`` that may have
    been billed (:func:`classify`): charged at its reservation, retried
    within the call's attempts, then the call fails (the episode ends ``infra_error``)."""


def _chain(exc: BaseException) -> list[BaseException]:
    """``exc`` and the exceptions it was raised from or during, in order (no cycles)."""
    out: list[BaseException] = []
    seen: set[int] = set()
    link: BaseException | None = exc
    while link is not None and id(link) not in seen:
        seen.add(id(link))
        out.append(link)
        link = link.__cause__ or link.__context__
    return out


def unreadable_reply(exc: BaseException) -> bool:
    """Did the provider answer HTTP 200 with a body we could not use? Then it may have billed it.

    litellm reports such a reply as a 500-class error (with a made-up status 500), so the status
    cannot tell it from a real provider 5xx. What tells them apart is the chain of exceptions: a
    real HTTP error was raised from the HTTP client's status error (``httpx.HTTPStatusError``, or
    the OpenAI SDK's ``APIStatusError`` carrying the provider's body); an unreadable 200 from a
    JSON decoding error, from our own :class:`UnusableReply`, or from
    litellm's conversion of the reply (:data:`_UNREADABLE_REPLY_MARKERS`)."""
    chain = _chain(exc)
    for link in chain:
        module = type(link).__module__
        if type(link).__name__ == "HTTPStatusError" and module.startswith("httpx"):
            return False
        if module.startswith("openai") and isinstance(getattr(link, "body", None), dict):
            return False  # the SDK read the provider's error body: a real HTTP error status
    for link in chain:
        if isinstance(link, (UnusableReply, json.JSONDecodeError)):
            return True
        if any(m in str(link) for m in _UNREADABLE_REPLY_MARKERS):
            return True
    return False


def too_deep_reply(exc: BaseException) -> bool:
    """Did an HTTP 200 reply arrive that nests deeper than Python's JSON reader goes?

    The OpenAI SDK decodes the body with ``json.loads``, which recurses once per level: a reply
    whose tool-call arguments are a JSON object nested 200,000 levels deep raises
    ``RecursionError`` there, and litellm reports it as a 500 (``OpenAIError`` raised from the
    ``RecursionError``). No HTTP status error is in such a chain: the provider answered 200, with
    what the model wrote."""
    chain = _chain(exc)
    for link in chain:
        if type(link).__name__ == "HTTPStatusError" and type(link).__module__.startswith("httpx"):
            return False
        if type(link).__module__.startswith("openai") and isinstance(getattr(link, "body", None), dict):
            return False
    return any(isinstance(link, RecursionError) for link in chain)


def classify(exc: BaseException, secrets: Iterable[str | None] = ()) -> Classified:
    """The error class of an exception raised by one litellm call."""
    litellm = import_litellm()
    unreadable = reply_200 = False
    message = scrub(f"{type(exc).__name__}: {exc}", secrets)[:MAX_MESSAGE_CHARS]
    status = getattr(exc, "status_code", None)
    status = status if isinstance(status, int) else None
    kind: LLMErrorKind | None
    if too_deep_reply(exc):
        # the model's reply, unreadable for its nesting: its failure (never retried, never a
        # resume's), charged at the reservation like any reply that arrived and was not used
        detail = "the provider's HTTP 200 reply nests deeper than a JSON reader goes (the model's reply, not used)"
        return Classified("invalid_reply", f"{detail}; {message}"[:MAX_MESSAGE_CHARS], None, 200, maybe_billed=True)
    if isinstance(exc, litellm.ContextWindowExceededError):
        kind = "context_length"
    elif isinstance(exc, litellm.RateLimitError):
        kind = "rate_limit"
    elif isinstance(exc, (litellm.Timeout, asyncio.TimeoutError, TimeoutError)):
        kind = "timeout"
    elif isinstance(exc, (litellm.AuthenticationError, litellm.PermissionDeniedError)):
        kind = "auth"
    elif isinstance(
        exc, (litellm.InternalServerError, litellm.ServiceUnavailableError, litellm.BadGatewayError, litellm.APIConnectionError)
    ):
        kind = "server_error"
        unreadable = reply_200 = unreadable_reply(exc)
    elif unreadable_reply(exc):  # our own UnusableReply, or a decoding error litellm let through
        kind = "server_error"
        unreadable = reply_200 = True
    elif isinstance(
        exc, (litellm.BadRequestError, litellm.NotFoundError, litellm.UnprocessableEntityError, litellm.UnsupportedParamsError)
    ):
        kind = _kind_of_status(400, str(exc)) or "bad_request"
    else:
        kind = _kind_of_status(status, str(exc))
        if kind is None:
            # unknown failure inside the client (malformed body, dropped connection): transient
            kind = "server_error"
            unreadable = True
    billed = kind == "timeout" or unreadable
    if reply_200:
        status = 200  # what the provider answered (litellm reports a made-up 500)
    return Classified(kind, message, retry_after_seconds(exc) if kind == "rate_limit" else None, status, maybe_billed=billed)


#: loggers of the HTTP clients under litellm that print request URLs (and so a base URL's
#: credentials) at DEBUG/INFO
URL_LOGGERS = ("openai._base_client", "httpx", "httpcore", "aiohttp.client", "LiteLLM", "LiteLLM Router")


class ScrubFilter:
    """A logging filter that scrubs a record's message (URL credentials, key-like strings)."""

    def filter(self, record: Any) -> bool:
        try:
            message = record.getMessage()
        except Exception:
            return True
        clean = scrub(message)
        if clean != message:
            record.msg, record.args = clean, ()
        return True


def install_log_scrubber() -> None:
    """Scrub what the HTTP client loggers print (idempotent)."""
    for name in URL_LOGGERS:
        logger = logging.getLogger(name)
        if not any(isinstance(f, ScrubFilter) for f in logger.filters):
            logger.addFilter(ScrubFilter())
