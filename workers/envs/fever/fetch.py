"""One HTTP GET of a Wikipedia answer, bounded in time and in size, redirects left to the caller.

Why not ``requests``: its ``timeout`` bounds each socket read, so a server that sends its headers
and then one byte every few seconds holds a request for as long as it likes (issue 35 item 7);
it reads a body whole and decodes gzip whole, so a 1 MB gzip body that expands to 1 GiB lands in
memory (item 8); and it follows redirects to any host (item 9). Here a request is one
``http.client`` exchange:

* a **deadline** (an absolute ``time.monotonic()``) for everything: each socket read waits at most
  what is left of it (and at most ``read_timeout``), and a watchdog shuts the socket at the
  deadline, so a server dripping its headers or its body is cut there (:class:`DeadlinePassed`);
* the body is read in chunks and decoded as it comes (gzip, deflate; nothing else is asked for),
  at most ``max_bytes`` decoded bytes kept, and no more than ``max_bytes`` read off the wire
  (:class:`TooLarge` as soon as either is passed, or when Content-Length says so up front);
* a redirect answer is returned with its ``Location`` and no body read: :class:`~.wiki.LiveSource`
  decides whether to follow it (only within the configured Wikipedia origin, each hop rate-limited).

A network failure (refused connection, a socket read that waits ``read_timeout`` for nothing, a
truncated or undecodable body) raises :class:`TransientError`: worth another try within the
deadline.
"""

from __future__ import annotations

import http.client
import socket
import ssl
import threading
import time
import urllib.request
import zlib
from dataclasses import dataclass
from functools import cache
from urllib.parse import urlsplit

import certifi

#: statuses whose ``Location`` is a redirect (RFC 9110 section 15.4)
REDIRECT_STATUSES = frozenset({301, 302, 303, 307, 308})
#: bytes asked of the socket per read
CHUNK = 64 * 1024
DEFAULT_PORTS = {"http": 80, "https": 443}


class DeadlinePassed(Exception):
    """The whole answer did not arrive before the deadline."""


class TooLarge(Exception):
    """The answer is larger than the cap (decoded, or as sent)."""


class TransientError(Exception):
    """The request failed in a way another try may not (network, truncated or undecodable body)."""


@dataclass(frozen=True)
class Answer:
    """One response: status, headers, where it was fetched from, the decoded body (empty for a
    redirect or an error status, whose bodies are not read) and the redirect's ``Location``."""

    url: str
    status: int
    headers: http.client.HTTPMessage
    body: bytes
    location: str | None


def origin(url: str) -> tuple[str, str, int]:
    """(scheme, host, port) of an http(s) URL, the port made explicit; ValueError for anything else."""
    parts = urlsplit(url)
    scheme = parts.scheme.lower()
    if scheme not in DEFAULT_PORTS or not parts.hostname:
        raise ValueError(f"not an http(s) URL: {url!r}")
    try:
        port = parts.port
    except ValueError:
        raise ValueError(f"bad port in {url!r}") from None
    return scheme, parts.hostname.lower(), port if port is not None else DEFAULT_PORTS[scheme]


@cache
def _tls() -> ssl.SSLContext:
    """Certificate checks against certifi's bundle (the one ``requests`` used)."""
    return ssl.create_default_context(cafile=certifi.where())


class _Decoder:
    """Content-Encoding ``gzip`` (several members too), ``deflate`` (zlib or raw, as urllib3
    reads it) or none, fed chunk by chunk into ``out`` with at most ``cap + 1`` bytes kept."""

    def __init__(self, encoding: str | None, cap: int, out: bytearray) -> None:
        self.kind = (encoding or "").strip().lower()
        self.cap = cap
        self.out = out
        self._z = self._new()
        self._first = True

    def _new(self) -> zlib._Decompress | None:
        if self.kind in ("gzip", "x-gzip"):
            return zlib.decompressobj(16 + zlib.MAX_WBITS)
        if self.kind == "deflate":
            return zlib.decompressobj()
        return None  # identity, or an encoding not asked for: kept as sent (as urllib3 does)

    def _room(self) -> int:
        return self.cap + 1 - len(self.out)

    def feed(self, data: bytes) -> None:
        if self._z is None:
            self.out += data
            self._check()
            return
        if self.kind == "deflate" and self._first:
            self._first = False
            try:
                zlib.decompressobj().decompress(data[:2])  # a zlib header, or raw deflate
            except zlib.error:
                self._z = zlib.decompressobj(-zlib.MAX_WBITS)  # raw deflate, no zlib header
        while data:
            try:
                piece = self._z.decompress(data, self._room())
            except zlib.error as exc:
                raise TransientError(f"the {self.kind} body cannot be decoded ({exc})") from None
            self.out += piece
            self._check()
            if self._z.eof:
                data = self._z.unused_data
                if data and self.kind != "deflate":
                    self._z = self._new()  # another gzip member
                    assert self._z is not None
                else:
                    data = b""
            else:
                data = self._z.unconsumed_tail

    def _check(self) -> None:
        if len(self.out) > self.cap:
            raise TooLarge(f"the decoded answer passes {self.cap} bytes")


def _connection(scheme: str, host: str, port: int, timeout: float) -> tuple[http.client.HTTPConnection, str]:
    """The connection for one request and what comes before the path on its request line: direct,
    or through the proxy the environment names (``https_proxy``/``http_proxy``, ``no_proxy``, as
    ``requests`` honoured them): a CONNECT tunnel for https, an absolute URL for http."""
    proxy = None if urllib.request.proxy_bypass(host) else urllib.request.getproxies().get(scheme)
    if proxy:
        p = urlsplit(proxy if "://" in proxy else f"http://{proxy}")
        p_host, p_port = p.hostname or "", p.port or 8080
        if scheme == "https":
            tunnel = http.client.HTTPSConnection(p_host, p_port, timeout=timeout, context=_tls())
            tunnel.set_tunnel(host, port)
            return tunnel, ""
        return http.client.HTTPConnection(p_host, p_port, timeout=timeout), f"http://{host}:{port}"
    if scheme == "https":
        return http.client.HTTPSConnection(host, port, timeout=timeout, context=_tls()), ""
    return http.client.HTTPConnection(host, port, timeout=timeout), ""


def _bound(conn: http.client.HTTPConnection, deadline: float, read_timeout: float, fired: threading.Event) -> None:
    """The next socket read waits at most what is left of the deadline (and ``read_timeout``)."""
    left = deadline - time.monotonic()
    if fired.is_set() or left <= 0:
        raise DeadlinePassed
    if conn.sock is not None:
        conn.sock.settimeout(min(read_timeout, left))


def get_once(
    url: str, *, headers: dict[str, str], deadline: float, read_timeout: float, max_bytes: int, chunk: int = CHUNK
) -> Answer:
    """GET ``url`` once (no redirect followed) by ``deadline``, the body kept when the status is
    2xx (or a 3xx without Location), decoded, at most ``max_bytes``. Raises DeadlinePassed,
    TooLarge, TransientError, or ValueError for a URL that is not http(s)."""
    scheme, host, port = origin(url)
    parts = urlsplit(url)
    left = deadline - time.monotonic()
    if left <= 0:
        raise DeadlinePassed
    timeout = min(read_timeout, left)
    conn, target = _connection(scheme, host, port, timeout)
    fired = threading.Event()

    def cut() -> None:  # the watchdog: wakes a read blocked on a server that drips
        fired.set()
        sock = conn.sock
        if sock is not None:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass

    watchdog = threading.Timer(left, cut)
    watchdog.daemon = True
    watchdog.start()
    try:
        path = (parts.path or "/") + (f"?{parts.query}" if parts.query else "")
        conn.request("GET", target + path, headers={**headers, "Accept-Encoding": "gzip, deflate", "Connection": "close"})
        _bound(conn, deadline, read_timeout, fired)
        response = conn.getresponse()
        _bound(conn, deadline, read_timeout, fired)
        location = response.getheader("Location")
        if response.status in REDIRECT_STATUSES and location:
            return Answer(url, response.status, response.headers, b"", location)
        if not 200 <= response.status < 400:
            return Answer(url, response.status, response.headers, b"", None)
        length = response.getheader("Content-Length")
        if length is not None and length.strip().isdigit() and int(length) > max_bytes:
            raise TooLarge(f"the answer says it is {int(length)} bytes, more than {max_bytes}")
        out = bytearray()
        decoder = _Decoder(response.getheader("Content-Encoding"), max_bytes, out)
        sent = 0
        while True:
            _bound(conn, deadline, read_timeout, fired)
            data = response.read1(chunk)
            if fired.is_set():
                raise DeadlinePassed
            if not data:
                break
            sent += len(data)
            if sent > max_bytes:
                raise TooLarge(f"the answer as sent passes {max_bytes} bytes")
            decoder.feed(data)
        return Answer(url, response.status, response.headers, bytes(out), None)
    except (DeadlinePassed, TooLarge, TransientError):
        raise
    except (OSError, http.client.HTTPException) as exc:  # refused, reset, a read timeout, truncated
        if fired.is_set() or time.monotonic() >= deadline:  # the last read's timeout was the deadline's
            raise DeadlinePassed from None
        raise TransientError(f"{type(exc).__name__}: {exc}") from None
    finally:
        watchdog.cancel()
        conn.close()
