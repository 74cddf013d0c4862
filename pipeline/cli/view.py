"""``recap view RUN_DIR ...``: the command line of the local web viewer (served by :mod:`reports.webview.server`).

Exit status: 0 stopped with Ctrl-C; 2 with one line for bad usage, unreadable runs or a port it
cannot listen on.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import TextIO

from pipeline.cli.common import EXIT_USAGE, CommandParser, HelpExit, UsageError, error_line
from reports.ports import VIEWER_PORT
from reports.views import ReportError
from reports.webview.data import Catalog
from reports.webview.server import HOST, ViewServer

_EPILOG = f"""\
examples:
  recap view runs/demo                        http://127.0.0.1:{VIEWER_PORT}/ over one run folder
  recap view runs/a runs/b --port 9000        two runs (compare them on the Compare page)
  recap view --port 0 runs/demo               any free port (the URL is printed)

Pages: runs, episodes (filters, sort, paging, search over messages), one episode (tree, steps,
every call's exact window), compare two runs or two arms. Loopback only; the run folders are
read, never written; part files a running sweep adds appear within a few seconds. Episode ids in
an HTML report (recap report) link here while the viewer runs on the default port.
exit status: 0 stopped with Ctrl-C; 2 bad usage, a missing run folder, or the port in use
"""


def parser(out: TextIO | None = None) -> CommandParser:
    """The ``recap view`` argument parser (``out``: where ``--help`` goes)."""
    p = CommandParser(
        prog="recap view",
        out=out,
        epilog=_EPILOG,
        description="Browse every episode of one or more run folders in a local web viewer (read-only).",
    )
    p.add_argument("run_dirs", nargs="+", metavar="RUN_DIR", help="run folder(s); several are browsed together")
    p.add_argument(
        "--port",
        type=int,
        default=VIEWER_PORT,
        metavar="N",
        help=f"port on 127.0.0.1 (default {VIEWER_PORT}; 0 = any free port)",
    )
    p.add_argument(
        "--poll",
        type=float,
        default=2.0,
        metavar="SECONDS",
        help="how often to look for new part files (default 2; 0 = never, a fixed snapshot)",
    )
    return p


def _start(argv: Sequence[str], out: TextIO, err: TextIO) -> ViewServer | int:
    """The listening server, or the exit status of a refusal (its line printed)."""
    port = VIEWER_PORT
    try:
        args = parser(out).parse_intermixed_args(list(argv))
        port = args.port
        if not 0 <= args.port <= 65535:
            raise UsageError("recap view: --port must be between 0 and 65535")
        if not args.poll >= 0 or args.poll > 3600:
            raise UsageError("recap view: --poll must be between 0 and 3600 seconds")
        catalog = Catalog(args.run_dirs, poll_s=args.poll)
        try:
            return ViewServer(catalog, args.port)
        except BaseException:
            catalog.close()
            raise
    except HelpExit as exc:
        return exc.status
    except UsageError as exc:
        print(error_line("view", exc), file=err)
        return EXIT_USAGE
    except ReportError as exc:
        print(error_line("view", exc), file=err)
        return EXIT_USAGE
    except OSError as exc:
        print(f"recap: error: view: cannot listen on {HOST}:{port}: {exc.strerror or exc}", file=err)
        return EXIT_USAGE


def view_main(argv: Sequence[str], *, stdout: TextIO | None = None, stderr: TextIO | None = None) -> int:
    """``recap view``: serve the run folders until Ctrl-C; exit 0, or 2 with one line for bad usage, unreadable
    runs or a port it cannot listen on."""
    out, err = stdout or sys.stdout, stderr or sys.stderr
    server = _start(argv, out, err)
    if isinstance(server, int):
        return server
    for s in server.catalog.snap.skipped:
        print(f"warning: {s.line()}", file=err)
    print(f"recap view: {server.url}  ({len(server.catalog.run_dirs)} run folder(s); Ctrl-C to stop)", file=out, flush=True)
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        server.server_close()
        server.catalog.close()
    return 0


def main(argv: list[str]) -> int:
    """``recap view ...`` on the process's stdout and stderr."""
    return view_main(argv)
