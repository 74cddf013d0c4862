"""Where FEVER's search answers come from: live Wikipedia (politely) or a snapshot of earlier runs.

The release sends ``requests.get("https://en.wikipedia.org/w/index.php?search=" + entity)`` with
spaces turned into ``+`` and nothing else escaped (fever-recap/hotpotqa/wikienv.py:99-102); this
module builds the same URL on any base URL and lets ``requests`` prepare it exactly as the
release's call did (so ``AT&T`` still sends ``search=AT&T`` and ``C#`` sends ``search=C``), then
adds what the release lacked: an honest User-Agent, the shared per-host rate limit, bounded
retries on 429/5xx that honour Retry-After, and bounds a hostile or broken server cannot undo
(issue 35 items 7-9, :mod:`.fetch`): one deadline per answer, retries included (``timeout``), a cap
on its decoded size (``too_large``, nothing stored), redirects only within the origin of the URL
asked (the configured Wikipedia's scheme, host and port), each hop rate-limited, at most
``max_redirects`` of them (``redirect``). An answer that cannot be had raises
:class:`WikiError`, so no observation is ever made from a failed request. Every answer read goes
to a :class:`~workers.envs.fever.pages.PageStore`; :class:`SnapshotSource` answers from recorded
pages only.
"""

from __future__ import annotations

import email.utils
import functools
import math
import platform
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from importlib import metadata
from typing import Any, Literal, Protocol
from urllib.parse import urljoin, urlsplit

import requests
from requests.models import PreparedRequest

from recap.env import EnvError
from schemas.kinds import EndReason
from workers.envs.fever.fetch import Answer, DeadlinePassed, TooLarge, TransientError, get_once, origin
from workers.envs.fever.pages import PageRecord, PageStore, Snapshot, sha256_hex
from workers.envs.fever.ratelimit import RateLimiter, shared_limiter

DEFAULT_WIKIPEDIA_URL = "https://en.wikipedia.org"
SEARCH_PATH = "/w/index.php?search="
#: the end reason of an episode stopped because a Wikipedia answer could not be had (the runtime
#: records an EnvError's own ``end_reason``; schemas.labels retries the ``unavailable`` kind)
WIKI_END_REASON: EndReason = "wiki_error"
PROJECT_URL = "https://github.com/ReCAP-Stanford/ReCAP"

#: the seconds one answer may take, retries and redirects included (issue 35 item 7)
DEFAULT_DEADLINE_S = 60.0
#: the decoded bytes one answer may have (issue 35 item 8): a Wikipedia article is well under this
DEFAULT_MAX_PAGE_BYTES = 5 * 1024 * 1024

WikiErrorKind = Literal[
    "unavailable", "snapshot_miss", "unreadable", "disambiguation_loop", "bad_url", "timeout", "too_large", "redirect"
]


class WikiError(EnvError):
    """A Wikipedia answer that cannot be had or read; ``kind`` says which and starts the message
    (``unavailable: ...``: how a resume tells the site failing from an outcome,
    schemas.labels.infra_failure), ``end_reason`` is the episode's end reason (:data:`WIKI_END_REASON`)."""

    end_reason: EndReason = WIKI_END_REASON

    def __init__(self, kind: WikiErrorKind, message: str) -> None:
        super().__init__(f"{kind}: {message}")
        self.kind = kind


@functools.cache
def user_agent() -> str:
    """``recap-eval/<version> (<project url>; FEVER evaluation) Python-http.client/<version>``: says who asks and why.
    Computed once per process: reading the installed version's metadata takes milliseconds, and a
    sweep's preflight and estimate make an environment per claim."""
    try:
        version = metadata.version("recap-eval")
    except metadata.PackageNotFoundError:
        version = "unknown"
    return f"recap-eval/{version} (+{PROJECT_URL}; FEVER evaluation of the ReCAP agent) Python-http.client/{platform.python_version()}"


def search_url(base_url: str, entity: str) -> str:
    """The request URL of a search, prepared as ``requests`` prepares the release's URL (wikienv.py:99-100)."""
    raw = base_url.rstrip("/") + SEARCH_PATH + entity.replace(" ", "+")
    prepared = PreparedRequest()
    try:
        prepared.prepare_url(raw, None)
    except requests.exceptions.RequestException as exc:
        raise WikiError("bad_url", f"cannot build a search URL from {raw!r}: {exc}") from None
    assert prepared.url is not None
    return prepared.url


class WikiSource(Protocol):
    """What the environment asks for: the HTML answer of one search URL, as text."""

    def fetch(self, url: str) -> str:
        """The answer's text; raises WikiError when there is none."""
        ...


@dataclass(frozen=True)
class RetryPolicy:
    """Bounded retries and bounds on one answer: ``attempts`` tries in all, waits doubling from
    ``backoff_s`` up to ``max_wait_s`` (a Retry-After header sets the wait, capped at
    ``max_wait_s``), each socket read waiting at most ``timeout_s``; ``deadline_s`` for the
    whole answer, retries, waits and redirects included (the rate limit's waits are not: they
    measure the run's pace, not the server); at most ``max_page_bytes`` decoded (a Wikipedia
    article is well under 5 MB); at most ``max_redirects`` redirects, all within the origin
    (scheme, host, port) of the URL asked."""

    attempts: int = 4
    backoff_s: float = 1.0
    max_wait_s: float = 60.0
    timeout_s: float = 20.0
    deadline_s: float = DEFAULT_DEADLINE_S
    max_page_bytes: int = DEFAULT_MAX_PAGE_BYTES
    max_redirects: int = 5


DEFAULT_POLICY = RetryPolicy()


def check_max_page_bytes(value: Any) -> int:
    """``value`` as a byte cap of one answer (a positive integer); else ValueError naming the option."""
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(
            f"wikipedia_max_page_bytes must be a positive number of bytes (default {DEFAULT_MAX_PAGE_BYTES}), got {value!r}"
        )
    return value


def check_deadline(value: Any) -> float:
    """``value`` as the seconds one answer may take (above 0, finite); else ValueError naming the option."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) or value <= 0:
        raise ValueError(
            f"wikipedia_deadline_s must be a number of seconds above 0 (default {DEFAULT_DEADLINE_S:g}), got {value!r}"
        )
    return float(value)


def retry_after_seconds(value: str | None, now: float | None = None) -> float | None:
    """Seconds a Retry-After header asks for (delta-seconds or an HTTP date); None when absent or unreadable."""
    if value is None:
        return None
    value = value.strip()
    if value.isdigit():
        return float(value)
    try:
        when = email.utils.parsedate_to_datetime(value)
    except (TypeError, ValueError):
        return None
    return max(0.0, when.timestamp() - (time.time() if now is None else now))


def _retryable(status: int) -> bool:
    return status == 429 or 500 <= status < 600


def _origin_text(o: tuple[str, str, int]) -> str:
    return f"{o[0]}://{o[1]}:{o[2]}"


def text_encoding(headers: Any, body: bytes) -> str:
    """The encoding ``requests``' ``Response.text`` would decode ``body`` with: the header's
    charset (``text/*`` without one: ISO-8859-1), else the guessed one, else UTF-8 (requests/models.py)."""
    declared = requests.utils.get_encoding_from_headers(headers)
    if declared:
        return str(declared)
    detect = getattr(requests.compat, "chardet", None)
    guessed = detect.detect(body)["encoding"] if detect is not None else None
    return str(guessed or "utf-8")


class LiveSource:
    """Live Wikipedia (or any server answering ``/w/index.php?search=``): rate-limited per host
    (each redirect hop too), retried within :class:`RetryPolicy`, one deadline and one size cap
    per answer, redirects only within the asked URL's origin; every answer read appended to ``store``."""

    def __init__(
        self,
        store: PageStore | None = None,
        *,
        limiter: RateLimiter | None = None,
        policy: RetryPolicy = DEFAULT_POLICY,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        self.store = store
        self.limiter = limiter if limiter is not None else shared_limiter()
        self.policy = policy
        self._sleep = sleep
        self._headers = {"User-Agent": user_agent(), "Accept": "*/*"}
        self.requests_sent = 0

    def fetch(self, url: str) -> str:
        """Fetch ``url``; raises WikiError: ``unavailable`` after the retries or on a status the
        server refuses with, ``timeout`` past the deadline, ``too_large`` past the size cap,
        ``redirect`` for a redirect off the origin or too many of them, ``bad_url``."""
        policy = self.policy
        try:
            home = origin(url)
        except ValueError as exc:
            raise WikiError("bad_url", str(exc)) from None
        deadline = [time.monotonic() + policy.deadline_s]
        last = ""
        attempt = 0
        for attempt in range(1, policy.attempts + 1):
            wait: float | None = None
            try:
                answer = self._follow(url, home, deadline)
            except TransientError as exc:
                last = str(exc)
            else:
                if 200 <= answer.status < 400:
                    return self._keep(url, answer)
                last = f"HTTP {answer.status}"
                if not _retryable(answer.status):
                    break
                wait = retry_after_seconds(answer.headers.get("Retry-After"))
            if attempt < policy.attempts:
                pause = min(policy.max_wait_s, policy.backoff_s * 2 ** (attempt - 1) if wait is None else wait)
                if time.monotonic() + pause >= deadline[0]:
                    last += f"; the next try would pass the {policy.deadline_s:g} s deadline"
                    break
                self._sleep(pause)
        raise WikiError("unavailable", f"Wikipedia answer for {url} could not be fetched ({last}, {attempt} attempt(s))")

    def _follow(self, url: str, home: tuple[str, str, int], deadline: list[float]) -> Answer:
        """One try: ``url`` and the redirects it leads to within ``home``, each hop waiting for the
        rate limit (that wait moves ``deadline[0]`` on by as much)."""
        policy = self.policy
        current = url
        for _hop in range(policy.max_redirects + 1):
            before = time.monotonic()
            self.limiter.acquire(urlsplit(current).netloc)
            deadline[0] += time.monotonic() - before
            self.requests_sent += 1
            try:
                answer = get_once(
                    current,
                    headers=self._headers,
                    deadline=deadline[0],
                    read_timeout=policy.timeout_s,
                    max_bytes=policy.max_page_bytes,
                )
            except DeadlinePassed:
                raise WikiError(
                    "timeout", f"Wikipedia answer for {url} did not arrive within its {policy.deadline_s:g} s deadline"
                ) from None
            except TooLarge as exc:
                raise WikiError("too_large", f"Wikipedia answer for {url} refused: {exc}") from None
            if answer.location is None:
                return answer
            target = requests.utils.requote_uri(urljoin(current, answer.location)).split("#", 1)[0]
            try:
                there = origin(target)
            except ValueError:
                there = None
            if there != home:
                raise WikiError(
                    "redirect", f"{current} redirects to {target}, outside the configured Wikipedia {_origin_text(home)}"
                )
            current = target
        raise WikiError("redirect", f"{url} redirects more than {policy.max_redirects} times")

    def _keep(self, url: str, answer: Answer) -> str:
        body = answer.body
        record = PageRecord(
            url=url,
            sha256=sha256_hex(body),
            status=answer.status,
            fetched_at=datetime.now(UTC).isoformat(timespec="milliseconds"),
            body=body,
            encoding=text_encoding(answer.headers, body),
            final_url=answer.url,
        )
        if self.store is not None:
            self.store.append(record)
        return record.text()


class SnapshotSource:
    """Answers only from recorded pages; a URL they do not hold raises WikiError("snapshot_miss")."""

    def __init__(self, snapshot: Snapshot) -> None:
        self.snapshot = snapshot

    def fetch(self, url: str) -> str:
        """The recorded answer's text."""
        record = self.snapshot.get(url)
        if record is None:
            raise WikiError("snapshot_miss", f"the snapshot {str(self.snapshot.folder)!r} holds no answer for {url}")
        return record.text()
