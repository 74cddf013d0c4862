"""A test double: a loopback stand-in for Wikipedia's ``/w/index.php?search=`` answering HTML shaped like the real site's.

Not used by any run unless asked: it lives here (not under tests/) so that bench/fever.py can serve
pages without importing the tests, and ``recap env standin fever --port N`` (or ``python -m
workers.envs.fever.standin --port N``) serves it until stopped (:func:`serve`), for trying FEVER
sweeps offline with ``wikipedia_url: http://127.0.0.1:N``. No machine here reaches Wikipedia, so the tests serve pages in its layout: an article (found
directly or through a redirect to ``/wiki/Title``), a list of search results, a disambiguation
page whose ``[entity]`` search gives results, the "no such page" search answer, 429 with
Retry-After, 500 and a slow answer. Every request is counted, so snapshot tests can show zero.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import TextIO
from urllib.parse import parse_qs, urlsplit

HEAD = (
    '<!DOCTYPE html>\n<html class="client-nojs" lang="en" dir="ltr">\n<head>\n<meta charset="UTF-8">\n'
    "<title>{title} - Wikipedia</title>\n</head>\n<body>\n"
    '<div id="mw-navigation"><ul><li><a href="/wiki/Main_Page">Main page</a></li>'
    '<li><a href="/wiki/Special:Random">Random article</a></li></ul></div>\n'
    '<main id="content"><h1 id="firstHeading">{title}</h1>\n<div id="bodyContent"><div id="mw-content-text">\n'
)
FOOT = (
    "</div></div></main>\n"
    '<div id="footer"><ul id="footer-info"><li>This page was last edited on 1 March 2024, at 10:00 (UTC).</li>\n'
    "<li>Text is available under the Creative Commons Attribution-ShareAlike License 4.0; additional terms may apply.</li></ul></div>\n"
    "</body>\n</html>\n"
)


def page(title: str, inner: str) -> str:
    """A whole HTML document around ``inner`` (the content area)."""
    return HEAD.format(title=title) + inner + FOOT


ARTICLE = page(
    "Nikolaj Coster-Waldau",
    '<div class="mw-parser-output"><p class="mw-empty-elt">\n</p>\n'
    "<p><b>Nikolaj William Coster-Waldau</b> (Danish: [ˈnikolaj ˈkʰʌstɐ ˈʋalˀdɑw]; born 27 July 1970) is a Danish actor "
    'and producer.<sup id="cite_ref-1" class="reference"><a href="#cite_note-1">[1]</a></sup> He graduated from the '
    '<a href="/wiki/Danish_National_School_of_Performing_Arts">Danish National School of Performing Arts</a> in '
    "Copenhagen in 1993, and had his breakthrough role in Denmark with the film <i>Nightwatch</i> (1994). He played "
    "Jaime Lannister in the HBO fantasy drama series <i>Game of Thrones</i>, for which he received two Primetime Emmy "
    "Award nominations.\n</p>\n"
    "<p>Coster-Waldau has appeared in numerous films in his native Denmark and Scandinavia, including <i>Headhunters</i> "
    "(2011) and <i>A Thousand Times Good Night</i> (2013). In the U.S. his debut film role was in the war film "
    "<i>Black Hawk Down</i> (2001), playing Medal of Honor recipient Gary Gordon. He then played a detective in the "
    "short-lived Fox television series <i>New Amsterdam</i> (2008) – and the Fox TV film <i>Virtuality</i> (2009).\n</p>\n"
    "<p>Early life</p>\n"
    "<ul><li>Born in Rudkøbing</li><li>Raised in Tranebjerg, on the island of Samsø</li><li>Actor</li></ul>\n"
    "<p>He has been a Goodwill Ambassador for the United Nations Development Programme since 2016. He lives in "
    "Copenhagen with his wife Nukâka Coster-Waldau. The couple has two daughters.</p>\n"
    "</div>\n",
)

SEARCH_RESULTS = page(
    "Search results",
    '<div class="searchresults"><p class="mw-search-createlink">The page "Nikolaj" does not exist.</p>\n'
    '<ul class="mw-search-results">\n'
    + "".join(
        f'<li class="mw-search-result"><div class="mw-search-result-heading"><a href="/wiki/{t.replace(" ", "_")}" '
        f'title="{t}">{t.replace("Nikolaj", "<span class=searchmatch>Nikolaj</span>")}</a> </div>'
        f'<div class="searchresult">… <span class="searchmatch">Nikolaj</span> is a given name …</div></li>\n'
        for t in (
            "Nikolaj Coster-Waldau",
            "Nikolaj Lie Kaas",
            "Nikolaj's Church",
            "Nikolaj Znaider",
            "Nikolaj Kirk",
            "Nikolaj Hübbe",
        )
    )
    + "</ul></div>\n",
)

DISAMBIGUATION = page(
    "Mercury",
    '<div class="mw-parser-output"><p><b>Mercury</b> commonly refers to:\n</p>\n'
    "<ul><li>Mercury (planet), the nearest planet to the Sun</li><li>Mercury (element), a metallic chemical element</li></ul>\n"
    "<p><b>Mercury</b> may also refer to:\n</p>\n"
    "<p>Mercury may refer to:</p>\n"
    "<ul><li>Mercury (mythology), a Roman god</li></ul></div>\n",
)

BRACKET_RESULTS = page(
    "Search results",
    '<div class="searchresults"><ul class="mw-search-results">\n'
    '<li><div class="mw-search-result-heading"><a href="/wiki/Mercury_(planet)">Mercury (planet)</a></div></li>\n'
    '<li><div class="mw-search-result-heading"><a href="/wiki/Mercury_(element)">Mercury (element)</a></div></li>\n'
    "</ul></div>\n",
)

MISSING = page(
    "Search results",
    '<div class="searchresults mw-searchresults-has-iw">\n'
    '<p class="mw-search-nonefound">There were no results matching the query.</p>\n'
    '<p class="mw-search-createlink">The page "Xyzzy qwerty" does not exist. You can create a draft and submit it for review.</p>\n'
    "</div>\n",
)

UNREADABLE = page(
    "Windows path",
    '<div class="mw-parser-output"><p>The default profile folder is C:\\Users\\example on most machines.</p></div>\n',
)


@dataclass
class Answer:
    """One canned answer: status, body, extra headers, seconds to wait before answering."""

    status: int = 200
    body: str = ""
    headers: dict[str, str] = field(default_factory=dict)
    delay: float = 0.0


def default_routes() -> dict[str, list[Answer]]:
    """Answers by the ``search`` value the server receives; a list is served in turn, its last entry repeated."""
    return {
        "Nikolaj Coster-Waldau": [Answer(body=ARTICLE)],
        "Coster-Waldau": [Answer(302, headers={"Location": "/wiki/Nikolaj_Coster-Waldau"})],
        "Nikolaj": [Answer(body=SEARCH_RESULTS)],
        "Mercury": [Answer(body=DISAMBIGUATION)],
        "[Mercury]": [Answer(body=BRACKET_RESULTS)],
        "Xyzzy qwerty": [Answer(body=MISSING)],
        "Busy": [Answer(429, "Too many requests", {"Retry-After": "7"}), Answer(body=ARTICLE)],
        "Broken": [Answer(500, "<html><body><p>Internal server error while rendering the page.</p></body></html>")],
        "Gone": [Answer(403, "<html><body><p>Forbidden: your client is not allowed here.</p></body></html>")],
        "Slow": [Answer(body=ARTICLE, delay=1.5)],
        "Windows path": [Answer(body=UNREADABLE)],
    }


class StandIn:
    """The server: start with :meth:`start`, read ``base_url``, ``requests`` (paths in order) and
    ``arrivals`` (their ``time.monotonic()`` on arrival, for rate tests), stop with :meth:`stop`."""

    def __init__(self, routes: dict[str, list[Answer]] | None = None) -> None:
        self.routes = routes if routes is not None else default_routes()
        self.requests: list[str] = []
        self.arrivals: list[float] = []
        self.user_agents: list[str] = []
        self._served: dict[str, int] = {}
        self._lock = threading.Lock()
        self._server: ThreadingHTTPServer | None = None
        self._thread: threading.Thread | None = None

    @property
    def base_url(self) -> str:
        """``http://127.0.0.1:<port>`` of the running server."""
        assert self._server is not None
        host, port = self._server.server_address[:2]
        return f"http://{host if isinstance(host, str) else host.decode()}:{port}"

    def _answer(self, path: str) -> Answer:
        parts = urlsplit(path)
        if parts.path.startswith("/wiki/"):
            key = parts.path[len("/wiki/") :].replace("_", " ")
        elif parts.path == "/w/index.php":
            key = parse_qs(parts.query, keep_blank_values=True).get("search", [""])[0]
        else:
            return Answer(404, "<html><body><p>No such path on this stand-in.</p></body></html>")
        answers = self.routes.get(key)
        if answers is None:
            return Answer(body=MISSING.replace("Xyzzy qwerty", key))
        with self._lock:
            n = self._served.get(key, 0)
            self._served[key] = n + 1
        return answers[min(n, len(answers) - 1)]

    def start(self, port: int = 0) -> StandIn:
        """Serve on 127.0.0.1:``port`` (0: a free port) from a background thread."""
        outer = self

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self) -> None:  # noqa: N802 (http.server's name)
                with outer._lock:
                    outer.arrivals.append(time.monotonic())
                    outer.requests.append(self.path)
                    outer.user_agents.append(self.headers.get("User-Agent", ""))
                answer = outer._answer(self.path)
                if answer.delay:
                    time.sleep(answer.delay)
                body = answer.body.encode("utf-8")
                try:
                    self.send_response(answer.status)
                    self.send_header("Content-Type", "text/html; charset=UTF-8")
                    self.send_header("Content-Length", str(len(body)))
                    for name, value in answer.headers.items():
                        self.send_header(name, value)
                    self.end_headers()
                    self.wfile.write(body)
                except (BrokenPipeError, ConnectionResetError):  # the client gave up (timeout tests)
                    pass

            def log_message(self, format: str, *args: object) -> None:
                pass

        self._server = ThreadingHTTPServer(("127.0.0.1", port), Handler)
        self._server.daemon_threads = True
        self._thread = threading.Thread(target=self._server.serve_forever, kwargs={"poll_interval": 0.02}, daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()
            self._server = None


def serve(port: int, out: TextIO | None = None, ready: threading.Event | None = None) -> int:
    """Serve the stand-in on 127.0.0.1:``port`` until SIGINT or SIGTERM, saying where on ``out``
    (stdout) first and setting ``ready`` then; 0 when stopped. The searches it answers are
    :func:`default_routes`' (any other is "no such page"). OSError when the port is taken."""
    out = out or sys.stdout
    stop = threading.Event()
    previous = {sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)}
    server = StandIn().start(port)
    try:
        print(f"FEVER Wikipedia stand-in on {server.base_url} (set wikipedia_url: {server.base_url})", file=out)
        print(f"answers: {', '.join(sorted(server.routes))}; other searches: no such page", file=out)
        print("stop with Ctrl-C (SIGINT) or SIGTERM", file=out, flush=True)
        if ready is not None:
            ready.set()
        while not stop.wait(0.2):
            pass
        print(f"stopped after {len(server.requests)} request{'s' if len(server.requests) != 1 else ''}", file=out, flush=True)
        return 0
    finally:
        server.stop()
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def main(argv: list[str] | None = None) -> int:
    """``python -m workers.envs.fever.standin [--port N]``: :func:`serve` (``recap env standin fever`` is the same)."""
    parser = argparse.ArgumentParser(prog="python -m workers.envs.fever.standin", description=serve.__doc__)
    parser.add_argument("--port", type=int, default=8080, help="the port on 127.0.0.1 (default 8080; 0: a free one)")
    return serve(parser.parse_args(argv).port)


if __name__ == "__main__":
    sys.exit(main())
