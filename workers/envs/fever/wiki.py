"""Where FEVER's search answers come from: live Wikipedia (politely) or a snapshot of earlier runs.

The release sends ``requests.get("https://en.wikipedia.org/w/index.php?search=" + entity)`` with
spaces turned into ``+`` and nothing else escaped (fever-recap/hotpotqa/wikienv.py:99-102); this
module builds the same URL on any base URL and lets ``requests`` prepare it exactly as the
release's call did (so ``AT&T`` still sends ``search=AT&T`` and ``C#`` sends ``search=C``), then
adds what the release lacked: an honest User-Agent, the shared per-host rate limit, a timeout and
bounded retries on 429/5xx that honour Retry-After. An answer that cannot be had raises
:class:`WikiError`, so no observation is ever made from a failed request. Every answer read goes
to a :class:`~workers.envs.fever.pages.PageStore`; :class:`SnapshotSource` answers from recorded
pages only.
"""

from __future__ import annotations

import email.utils
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from importlib import metadata
from typing import Literal, Protocol
from urllib.parse import urlsplit

import requests
from requests.models import PreparedRequest

from recap.env import EnvError
from schemas.kinds import EndReason
from workers.envs.fever.pages import PageRecord, PageStore, Snapshot, sha256_hex
from workers.envs.fever.ratelimit import RateLimiter, shared_limiter

DEFAULT_WIKIPEDIA_URL = "https://en.wikipedia.org"
SEARCH_PATH = "/w/index.php?search="
#: the end reason of an episode stopped because a Wikipedia answer could not be had (the runtime
#: records an EnvError's own ``end_reason``; schemas.labels retries the ``unavailable`` kind)
WIKI_END_REASON: EndReason = "wiki_error"
PROJECT_URL = "https://github.com/ReCAP-Stanford/ReCAP"

WikiErrorKind = Literal["unavailable", "snapshot_miss", "unreadable", "disambiguation_loop", "bad_url"]


class WikiError(EnvError):
    """A Wikipedia answer that cannot be had or read; ``kind`` says which and starts the message
    (``unavailable: ...``: how a resume tells the site failing from an outcome,
    schemas.labels.infra_failure), ``end_reason`` is the episode's end reason (:data:`WIKI_END_REASON`)."""

    end_reason: EndReason = WIKI_END_REASON

    def __init__(self, kind: WikiErrorKind, message: str) -> None:
        super().__init__(f"{kind}: {message}")
        self.kind = kind


def user_agent() -> str:
    """``recap-eval/<version> (<project url>; FEVER evaluation) requests/<version>``: says who asks and why."""
    try:
        version = metadata.version("recap-eval")
    except metadata.PackageNotFoundError:
        version = "unknown"
    return f"recap-eval/{version} (+{PROJECT_URL}; FEVER evaluation of the ReCAP agent) python-requests/{requests.__version__}"


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
    """Bounded retries: ``attempts`` tries in all, waits doubling from ``backoff_s`` up to ``max_wait_s``
    (a Retry-After header sets the wait, capped at ``max_wait_s``), each request limited to ``timeout_s``."""

    attempts: int = 4
    backoff_s: float = 1.0
    max_wait_s: float = 60.0
    timeout_s: float = 20.0


DEFAULT_POLICY = RetryPolicy()


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


class LiveSource:
    """Live Wikipedia (or any server answering ``/w/index.php?search=``): rate-limited per host,
    retried within :class:`RetryPolicy`, every answer read appended to ``store``."""

    def __init__(
        self,
        store: PageStore | None = None,
        *,
        limiter: RateLimiter | None = None,
        policy: RetryPolicy = DEFAULT_POLICY,
        sleep: Callable[[float], None] = time.sleep,
        session: requests.Session | None = None,
    ) -> None:
        self.store = store
        self.limiter = limiter if limiter is not None else shared_limiter()
        self.policy = policy
        self._sleep = sleep
        self._session = session if session is not None else requests.Session()
        self._session.headers["User-Agent"] = user_agent()
        self.requests_sent = 0

    def fetch(self, url: str) -> str:
        """Fetch ``url``; raises WikiError("unavailable") after the retries or on a status the server refuses with."""
        host = urlsplit(url).netloc
        last = ""
        for attempt in range(1, self.policy.attempts + 1):
            self.limiter.acquire(host)
            self.requests_sent += 1
            try:
                response = self._session.get(url, timeout=self.policy.timeout_s)
            except requests.exceptions.RequestException as exc:  # timeout, refused connection, bad redirect
                last, wait = f"{type(exc).__name__}: {exc}", None
            else:
                if response.ok:
                    return self._keep(url, response)
                last = f"HTTP {response.status_code}"
                if not _retryable(response.status_code):
                    break
                wait = retry_after_seconds(response.headers.get("Retry-After"))
            if attempt < self.policy.attempts:
                backoff = self.policy.backoff_s * 2 ** (attempt - 1)
                self._sleep(min(self.policy.max_wait_s, backoff if wait is None else wait))
        raise WikiError("unavailable", f"Wikipedia answer for {url} could not be fetched ({last}, {attempt} attempt(s))")

    def _keep(self, url: str, response: requests.Response) -> str:
        body = response.content
        # Response.text decodes with the header's charset, else the guessed one (requests/models.py)
        encoding = response.encoding or response.apparent_encoding or "utf-8"
        record = PageRecord(
            url=url,
            sha256=sha256_hex(body),
            status=response.status_code,
            fetched_at=datetime.now(UTC).isoformat(timespec="milliseconds"),
            body=body,
            encoding=encoding,
            final_url=response.url,
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
