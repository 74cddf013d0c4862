"""The HTTP side of ``recap view``: routes and safety rules (the command line is :mod:`pipeline.cli.view`).

Safety rules, all enforced here:

* it listens on 127.0.0.1 only (no option to change that) and answers only requests whose
  ``Host`` is the loopback address it listens on (a web page on another site cannot reach it
  through DNS rebinding);
* only GET and HEAD; every route is a fixed name, static files come from a fixed list, and the
  one file served from a run folder is that folder's ``report/report.html``;
* every parameter is checked (:class:`reports.webview.data.BadRequest` -> 400/404/409 with a
  one-line message); anything unexpected is a 500 with one line, never a traceback;
* no secret is served: pages show table rows (which hold no keys: the pipeline keeps credentials
  out of rows) and a sweep file with secret-like values redacted; nothing reads the environment;
* responses carry a Content-Security-Policy that allows only this origin's own script and style.
"""

from __future__ import annotations

import logging
import sys
import threading
from collections.abc import Sequence
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlsplit

from reports.ports import VIEWER_PORT
from reports.views import ReportError
from reports.webview import data as D
from reports.webview import pages

log = logging.getLogger(__name__)
HOST = "127.0.0.1"
STATIC_DIR = Path(__file__).resolve().with_name("static")
STATIC = {"app.css": "text/css; charset=utf-8", "app.js": "text/javascript; charset=utf-8"}
#: a 1x1 transparent GIF: the HTML report loads it to learn that a viewer is running
PING_GIF = bytes.fromhex("47494638396101000100800000000000ffffff21f90401000000002c00000000010001000002024401003b")
CSP = "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self'; connect-src 'self'; base-uri 'none'; form-action 'self'; frame-ancestors 'none'"


class ViewServer(ThreadingHTTPServer):
    """The viewer's HTTP server: bound to 127.0.0.1 (``port`` 0 = any free port), one thread per request, all
    serving one :class:`reports.webview.data.Catalog`."""

    daemon_threads = True

    def __init__(self, catalog: D.Catalog, port: int = 0) -> None:
        self.catalog = catalog
        super().__init__((HOST, port), Handler)

    @property
    def url(self) -> str:
        """The viewer's base URL (with the port actually bound)."""
        return f"http://{HOST}:{self.server_address[1]}/"


class Handler(BaseHTTPRequestHandler):
    """One request: the host check, routing to a fixed route, and one-line errors (see the module docstring's safety rules)."""

    server: ViewServer
    server_version = "recap-view"
    sys_version = ""

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 - quiet: one line per error only
        """Silenced: the standard per-request access log would flood the terminal; errors are printed by :meth:`do_GET`."""
        return

    # -- plumbing -------------------------------------------------------------------------------------
    def _send(self, status: int, body: bytes, ctype: str, extra: dict[str, str] | None = None) -> None:
        self.send_response(status)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        self.send_header("Referrer-Policy", "no-referrer")
        self.send_header("Content-Security-Policy", CSP)
        for k, v in (extra or {}).items():
            self.send_header(k, v)
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def _html(self, text: str, status: int = 200) -> None:
        self._send(status, text.encode("utf-8"), "text/html; charset=utf-8")

    def _error(self, status: int, message: str) -> None:
        self._html(pages.error_page(status, message), status)

    def do_HEAD(self) -> None:  # noqa: N802
        """HEAD is GET without the body (``_send`` leaves it out)."""
        self.do_GET()

    def do_GET(self) -> None:  # noqa: N802
        """Serve a GET: refuse a foreign ``Host``, route by path, and turn every error into a status and one line
        (400/404/409 for refused requests, 500 otherwise)."""
        try:
            if not self._host_ok():
                self._error(400, "this viewer answers only on its loopback address")
                return
            parts = urlsplit(self.path)
            params = parse_qs(parts.query, keep_blank_values=True, max_num_fields=64)
            route = ROUTES.get(parts.path)
            if route is None:
                self._error(404, f"no page {parts.path}")
                return
            route(self, params)
        except D.BadRequest as exc:
            self._error(exc.status, str(exc))
        except (ValueError, ReportError) as exc:
            self._error(400, str(exc).splitlines()[0] if str(exc) else "bad request")
        except (BrokenPipeError, ConnectionResetError):
            pass
        except Exception as exc:  # noqa: BLE001 - one line to the log and to the client, no traceback
            print(
                f"recap view: error on {self.path[:200]}: {type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}",
                file=sys.stderr,
            )
            try:
                self._error(500, "internal error (see the terminal running recap view)")
            except OSError:
                pass

    def _not_allowed(self) -> None:
        self._send(405, b"method not allowed\n", "text/plain; charset=utf-8", {"Allow": "GET, HEAD"})

    do_POST = do_PUT = do_DELETE = do_PATCH = do_OPTIONS = _not_allowed  # noqa: N815

    def _host_ok(self) -> bool:
        host = (self.headers.get("Host") or "").strip().lower()
        port = self.server.server_address[1]
        return host in (f"127.0.0.1:{port}", f"localhost:{port}")

    # -- routes ---------------------------------------------------------------------------------------
    def runs(self, params: dict[str, list[str]]) -> None:
        """The runs page; a run links its report only when ``report/report.html`` exists in its folder."""
        _only(params)
        snap = self.server.catalog.snap
        rows = D.runs(snap)
        reports = {r["run_dir"] for r in rows if (Path(r["run_dir"]) / "report" / "report.html").is_file()}
        self._html(pages.runs_page(snap, rows, reports))

    def spec(self, params: dict[str, list[str]]) -> None:
        """A run's sweep file (``run=``), secrets redacted."""
        _only(params, "run")
        snap = self.server.catalog.snap
        run_id = _one(params, "run")
        self._html(pages.spec_page(snap, run_id, D.run_spec(snap, run_id)))

    def report(self, params: dict[str, list[str]]) -> None:
        """A run's own ``report/report.html`` (``run=``), served under a policy that lets its inline script and
        style run; 404 when there is none."""
        _only(params, "run")
        snap = self.server.catalog.snap
        run_id = _one(params, "run")
        folder = next((r["run_dir"] for r in D.runs(snap) if r["run_id"] == run_id), None)
        if folder is None:
            raise D.BadRequest(f"no run {run_id!r}", 404)
        path = Path(folder) / "report" / "report.html"
        if not path.is_file():
            raise D.BadRequest(f"run {run_id!r} has no report (recap report {folder})", 404)
        # the report is a static page with inline script and style: its own policy
        body = path.read_bytes()
        self.send_response(200)
        self.send_header("Content-Type", "text/html; charset=utf-8")
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        self.send_header(
            "Content-Security-Policy",
            "default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; "
            "img-src 'self' data:; frame-ancestors 'none'",
        )
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def episodes(self, params: dict[str, list[str]]) -> None:
        """The episode list (filters, search, sort and page from the URL)."""
        snap = self.server.catalog.snap
        lq = D.parse_list_query(params, snap)
        self._html(pages.episodes_page(snap, D.episode_list(snap, lq)))

    def episode(self, params: dict[str, list[str]]) -> None:
        """One episode (``id=``, ``run=`` when several runs hold it, ``hit=`` to open a message)."""
        _only(params, "id", "run", "hit")
        snap = self.server.catalog.snap
        run_id, eid = D.find_episode(snap, _one(params, "id"), _one(params, "run", required=False) or None)
        hit = _int(params, "hit") if _one(params, "hit", required=False) else None
        self._html(pages.episode_page(snap, D.episode(snap, run_id, eid), hit))

    def window(self, params: dict[str, list[str]]) -> None:
        """One call's window (``id``, ``run``, ``call``); ``fragment=1`` returns just the HTML the episode page inserts."""
        _only(params, "id", "run", "call", "fragment")
        snap = self.server.catalog.snap
        run_id, eid = D.find_episode(snap, _one(params, "id"), _one(params, "run", required=False) or None)
        call, msgs = D.call_window(snap, run_id, eid, _int(params, "call"))
        if _one(params, "fragment", required=False) == "1":
            self._html(pages.window_fragment(run_id, eid, call, msgs))
        else:
            self._html(pages.window_page(snap, run_id, eid, call, msgs))

    def compare(self, params: dict[str, list[str]]) -> None:
        """The compare page (``kind`` run or arm, default run); it compares only once ``a`` or ``b`` is given."""
        _only(params, "kind", "a", "b")
        snap = self.server.catalog.snap
        kind = _one(params, "kind", required=False) or "run"
        a, b = _one(params, "a", required=False), _one(params, "b", required=False)
        cmp = D.compare(snap, kind, a, b) if (a or b) else None
        self._html(pages.compare_page(snap, D.compare_choices(snap), cmp, kind, a, b))

    def static(self, name: str) -> None:
        """One file of the fixed static list (the caller checked the name)."""
        self._send(200, (STATIC_DIR / name).read_bytes(), STATIC[name], {"Cache-Control": "max-age=60"})

    def ping(self, params: dict[str, list[str]]) -> None:
        """A 1x1 GIF that other origins may load: the HTML report uses it to learn that a viewer is running and link to it."""
        self._send(200, PING_GIF, "image/gif", {"Cross-Origin-Resource-Policy": "cross-origin"})


def _static_route(name: str) -> Any:
    """The route of one static file: no query parameters, then the file."""

    def route(handler: Any, params: dict[str, list[str]]) -> Any:
        _only(params)
        return handler.static(name)

    return route


def _only(params: dict[str, list[str]], *allowed: str) -> None:
    unknown = sorted(set(params) - set(allowed))
    if unknown:
        raise D.BadRequest(f"unknown parameter(s): {', '.join(unknown)}")


def _one(params: dict[str, list[str]], name: str, *, required: bool = True) -> str:
    values = params.get(name) or [""]
    if len(values) > 1:
        raise D.BadRequest(f"give {name} once")
    if required and not values[0]:
        raise D.BadRequest(f"missing parameter {name}")
    return values[0]


def _int(params: dict[str, list[str]], name: str) -> int:
    text = _one(params, name)
    if not text.isdigit() or len(text) > 9:
        raise D.BadRequest(f"{name} must be a whole number >= 0")
    return int(text)


ROUTES: dict[str, Any] = {
    "/": Handler.runs,
    "/runs": Handler.runs,
    "/spec": Handler.spec,
    "/report": Handler.report,
    "/episodes": Handler.episodes,
    "/episode": Handler.episode,
    "/window": Handler.window,
    "/compare": Handler.compare,
    "/ping.gif": Handler.ping,
    **{f"/static/{n}": _static_route(n) for n in STATIC},
}


# -- running it ---------------------------------------------------------------------------------------


def serve(run_dirs: Sequence[str | Path], port: int = VIEWER_PORT, *, poll_s: float = 2.0) -> tuple[ViewServer, threading.Thread]:
    """Start a viewer in a background thread (tests, the bench); ``server.shutdown()`` ends it."""
    catalog = D.Catalog(run_dirs, poll_s=poll_s)
    try:
        server = ViewServer(catalog, port)
    except BaseException:
        catalog.close()
        raise
    thread = threading.Thread(target=server.serve_forever, name="recap-view", daemon=True)
    thread.start()
    return server, thread


def stop(server: ViewServer, thread: threading.Thread) -> None:
    """Stop a viewer started by :func:`serve`: the server, its thread (up to 5 s), its socket and the catalog's refresher."""
    server.shutdown()
    thread.join(timeout=5)
    server.server_close()
    server.catalog.close()
