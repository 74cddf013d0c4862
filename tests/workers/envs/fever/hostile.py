"""Hostile Wikipedia servers on loopback, and the attacks of issue 35 items 7-9 played against :class:`LiveSource`.

One definition of each attack, shared by ``test_hostile_pages.py`` (which asserts each outcome
exactly) and the chaos lab's ``wiki`` scenario (``tests/pipeline/chaos/wiki.py``: tried / held).
Every server is a real HTTP server on a loopback address; every fetch goes through the real
socket code. Each attack returns an :class:`Outcome`: the error's kind and message (None when
the page was served), the seconds the fetch took, the requests each server saw, the rows the
worker would write (``RunRecords.take``), the rate limiter's bookings and the fetch's peak
Python memory (tracemalloc).
"""

from __future__ import annotations

import gzip
import threading
import time
import tracemalloc
import uuid
import zlib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import cache
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any
from urllib.parse import parse_qs, urlsplit

from workers.envs.fever.pages import RunRecords
from workers.envs.fever.ratelimit import TokenBucket
from workers.envs.fever.wiki import LiveSource, RetryPolicy, WikiError, search_url

PAGE = b"<html><body><div id='mw-content-text'><p>A short article.</p></div></body></html>"
MiB = 1024 * 1024

Route = Callable[[BaseHTTPRequestHandler], None]


class Server:
    """A loopback HTTP server answering by the ``search`` value (or the path) with a route."""

    def __init__(self, routes: dict[str, Route], host: str = "127.0.0.1", port: int = 0) -> None:
        self.routes = routes
        self.hits: list[str] = []
        outer = self

        class Handler(BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"

            def do_GET(self) -> None:  # noqa: N802 (http.server's name)
                outer.hits.append(self.path)
                parts = urlsplit(self.path)
                key = parse_qs(parts.query).get("search", [parts.path])[0]
                route = outer.routes.get(key, lambda h: send(h, 200, PAGE))
                try:
                    route(self)
                except (BrokenPipeError, ConnectionResetError, OSError):  # the client hung up: what we want
                    pass
                self.close_connection = True

            def log_message(self, format: str, *args: object) -> None:
                pass

        self._server = ThreadingHTTPServer((host, port), Handler)
        self._server.daemon_threads = True
        threading.Thread(target=self._server.serve_forever, kwargs={"poll_interval": 0.02}, daemon=True).start()

    @property
    def port(self) -> int:
        return int(self._server.server_address[1])

    @property
    def base_url(self) -> str:
        return f"http://{self._server.server_address[0]}:{self.port}"

    def stop(self) -> None:
        self._server.shutdown()
        self._server.server_close()


def send(h: BaseHTTPRequestHandler, status: int, body: bytes, headers: dict[str, str] | None = None) -> None:
    h.send_response(status)
    h.send_header("Content-Type", "text/html; charset=UTF-8")
    h.send_header("Content-Length", str(len(body)))
    for k, v in (headers or {}).items():
        h.send_header(k, v)
    h.end_headers()
    h.wfile.write(body)


def drip(every_s: float, count: int) -> Route:
    """Headers at once (a Content-Length of ``count`` bytes), then one byte every ``every_s`` seconds."""

    def route(h: BaseHTTPRequestHandler) -> None:
        h.send_response(200)
        h.send_header("Content-Type", "text/html; charset=UTF-8")
        h.send_header("Content-Length", str(count))
        h.end_headers()
        for _ in range(count):
            time.sleep(every_s)
            h.wfile.write(b"x")
            h.wfile.flush()

    return route


def drip_headers(every_s: float, count: int) -> Route:
    """The status line, then the headers one byte every ``every_s`` seconds (``count`` padding bytes)."""

    def route(h: BaseHTTPRequestHandler) -> None:
        h.wfile.write(b"HTTP/1.1 200 OK\r\nX-Pad: ")
        for _ in range(count):
            time.sleep(every_s)
            h.wfile.write(b"x")
            h.wfile.flush()
        h.wfile.write(b"\r\nContent-Length: %d\r\n\r\n" % len(PAGE) + PAGE)

    return route


def slow_500(delay_s: float) -> Route:
    """A 500 after ``delay_s`` seconds (every retry waits as long)."""

    def route(h: BaseHTTPRequestHandler) -> None:
        time.sleep(delay_s)
        send(h, 500, b"busy")

    return route


@cache
def gzip_bomb(decoded: int) -> bytes:
    """``decoded`` zero bytes as one gzip member (1 GiB is about 1 MB)."""
    c = zlib.compressobj(9, zlib.DEFLATED, 16 + zlib.MAX_WBITS)
    block = b"\0" * MiB
    parts = [c.compress(block) for _ in range(decoded // MiB)]
    parts.append(c.flush())
    return b"".join(parts)


def gzipped(body: bytes, headers: dict[str, str] | None = None) -> Route:
    return lambda h: send(h, 200, body, {"Content-Encoding": "gzip", **(headers or {})})


def big_plain(size: int, *, with_length: bool) -> Route:
    """``size`` bytes of HTML, with a Content-Length or close-delimited (sent in 1 MiB writes)."""

    def route(h: BaseHTTPRequestHandler) -> None:
        h.send_response(200)
        h.send_header("Content-Type", "text/html; charset=UTF-8")
        if with_length:
            h.send_header("Content-Length", str(size))
        else:
            h.send_header("Connection", "close")
        h.end_headers()
        block = b"<p>" + b"a" * (MiB - 7) + b"</p>\n"
        for _ in range(size // MiB):
            h.wfile.write(block)

    return route


def redirect(location: str | Callable[[], str], status: int = 302) -> Route:
    return lambda h: send(h, status, b"", {"Location": location() if callable(location) else location})


@dataclass
class Outcome:
    """What one attack did (see the module doc)."""

    kind: str | None
    message: str
    elapsed_s: float
    hits: dict[str, int]
    rows: list[Any]
    acquired: list[str] = field(default_factory=list)
    peak_bytes: int = 0

    def detail(self) -> str:
        return f"{self.kind or 'served'} in {self.elapsed_s:.1f} s, hits {self.hits}, {len(self.rows)} row(s), peak {self.peak_bytes / MiB:.1f} MiB"


class RecordingLimiter(TokenBucket):
    """The shared token bucket, remembering every host it was asked for."""

    def __init__(self, rate: float = 1000.0, burst: int = 1000) -> None:
        super().__init__(rate, burst)
        self.hosts: list[str] = []

    def acquire(self, host: str) -> None:
        self.hosts.append(host)
        super().acquire(host)


@contextmanager
def servers(**routes_by_name: tuple[dict[str, Route], str, int]) -> Iterator[dict[str, Server]]:
    started: dict[str, Server] = {}
    try:
        for name, (routes, host, port) in routes_by_name.items():
            started[name] = Server(routes, host, port)
        yield started
    finally:
        for s in started.values():
            s.stop()


def play(base_url: str, entity: str, watched: dict[str, Server], policy: RetryPolicy, *, measure_memory: bool = False) -> Outcome:
    """Fetch ``entity``'s search page from ``base_url`` as an episode would; the outcome."""
    records = RunRecords()
    limiter = RecordingLimiter()
    source = LiveSource(records.store, limiter=limiter, policy=policy, sleep=time.sleep)
    if measure_memory:
        tracemalloc.start()
    t0 = time.monotonic()
    kind, message = None, ""
    try:
        source.fetch(search_url(base_url, entity))
    except WikiError as exc:
        kind, message = exc.kind, str(exc)
    elapsed = time.monotonic() - t0
    peak = 0
    if measure_memory:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    return Outcome(
        kind,
        message,
        elapsed,
        {n: len(s.hits) for n, s in watched.items()},
        records.take("e1", uuid.uuid4().hex),  # a fresh run id: every body read is handed over
        limiter.hosts,
        peak,
    )


# -- the attacks (each: one fresh set of servers, one fetch) -----------------------------------------

#: a small deadline keeps the attacks quick; the server drips for longer than it
DEADLINE_S = 2.0
SLACK_S = 1.0


def attack_drip() -> Outcome:
    """Item 7: headers, then a byte every 0.5 s for 12 s; the deadline is 2 s."""
    with servers(wiki=({"Drip": drip(0.5, 24)}, "127.0.0.1", 0)) as s:
        return play(s["wiki"].base_url, "Drip", s, RetryPolicy(deadline_s=DEADLINE_S))


def attack_drip_headers() -> Outcome:
    """Item 7: the headers themselves dripped, a byte every 0.5 s for 12 s."""
    with servers(wiki=({"DripHeaders": drip_headers(0.5, 24)}, "127.0.0.1", 0)) as s:
        return play(s["wiki"].base_url, "DripHeaders", s, RetryPolicy(deadline_s=DEADLINE_S))


def attack_slow_retries() -> Outcome:
    """Item 7, retries included: each try answers 500 after 1.5 s; four tries would take 13 s."""
    with servers(wiki=({"Slow500": slow_500(1.5)}, "127.0.0.1", 0)) as s:
        return play(s["wiki"].base_url, "Slow500", s, RetryPolicy(deadline_s=DEADLINE_S, backoff_s=1.0))


def attack_gzip_bomb(decoded: int = 1024 * MiB) -> Outcome:
    """Item 8: a gzip body of about ``decoded / 1000`` bytes that expands to ``decoded``."""
    with servers(wiki=({"Bomb": gzipped(gzip_bomb(decoded))}, "127.0.0.1", 0)) as s:
        return play(s["wiki"].base_url, "Bomb", s, RetryPolicy(), measure_memory=True)


def attack_big_page(size: int = 54 * MiB, *, with_length: bool = True) -> Outcome:
    """Item 8: a plain page of ``size`` bytes (with a Content-Length, or sent until the connection closes)."""
    with servers(wiki=({"Big": big_plain(size, with_length=with_length)}, "127.0.0.1", 0)) as s:
        return play(s["wiki"].base_url, "Big", s, RetryPolicy(), measure_memory=True)


def attack_small_gzip_page() -> Outcome:
    """Control for item 8: an ordinary gzip-encoded article is served and stored, decoded."""
    with servers(wiki=({"Small": gzipped(gzip.compress(PAGE))}, "127.0.0.1", 0)) as s:
        return play(s["wiki"].base_url, "Small", s, RetryPolicy())


def attack_cross_host() -> Outcome:
    """Item 9: a redirect to another loopback host (127.0.0.2, the same port) serving a page."""
    with servers(wiki=({}, "127.0.0.1", 0)) as s:
        other = Server({}, "127.0.0.2", s["wiki"].port)
        try:
            s["wiki"].routes["Away"] = redirect(f"http://127.0.0.2:{other.port}/wiki/Elsewhere")
            return play(s["wiki"].base_url, "Away", {**s, "other": other}, RetryPolicy())
        finally:
            other.stop()


def attack_cross_port() -> Outcome:
    """Item 9: a redirect to the same host on another port."""
    with servers(wiki=({}, "127.0.0.1", 0), other=({}, "127.0.0.1", 0)) as s:
        s["wiki"].routes["Away"] = redirect(f"{s['other'].base_url}/wiki/Elsewhere")
        return play(s["wiki"].base_url, "Away", s, RetryPolicy())


def attack_scheme_change() -> Outcome:
    """Item 9: a redirect to https on the same host and port."""
    with servers(wiki=({}, "127.0.0.1", 0)) as s:
        s["wiki"].routes["Away"] = redirect(f"https://127.0.0.1:{s['wiki'].port}/wiki/Elsewhere")
        return play(s["wiki"].base_url, "Away", s, RetryPolicy())


def attack_redirect_loop(max_redirects: int = 5) -> Outcome:
    """Item 9: every answer redirects to the next page of the same host."""
    routes: dict[str, Route] = {f"/wiki/Loop{n}": redirect(f"/wiki/Loop{n + 1}") for n in range(50)}
    routes["Loop"] = redirect("/wiki/Loop0")
    with servers(wiki=(routes, "127.0.0.1", 0)) as s:
        return play(s["wiki"].base_url, "Loop", s, RetryPolicy(max_redirects=max_redirects))


def attack_same_host_redirect() -> Outcome:
    """Item 9, the allowed case: a redirect to an article of the same host, served, each hop booked."""
    with servers(wiki=({"Hop": redirect("/wiki/Article")}, "127.0.0.1", 0)) as s:
        return play(s["wiki"].base_url, "Hop", s, RetryPolicy())


def same_host_hops_wait(rate: float = 2.0) -> list[float]:
    """Item 9: the waits a one-token bucket at ``rate``/s imposes on one search that redirects once
    (a clock that does not move: each hop must book its own slot)."""
    waits: list[float] = []
    bucket = TokenBucket(rate, 1, clock=lambda: 0.0, sleep=waits.append)
    with servers(wiki=({"Hop": redirect("/wiki/Article")}, "127.0.0.1", 0)) as s:
        LiveSource(None, limiter=bucket, policy=RetryPolicy()).fetch(search_url(s["wiki"].base_url, "Hop"))
    return waits
