"""``recap report`` and ``recap sql``: the command-line faces of the reports package.

The pipeline CLI hands its remaining arguments to :func:`report_main` or :func:`sql_main`; both
return an exit status and print one-line errors, never tracebacks. ``recap report``: 0 ok, 1 a
problem with the runs' data or the options, 2 bad usage, a folder that is not a run folder (no
run.json) or an output folder holding files a report did not write (nothing is written then). ``recap sql``: 0 ok, 2 for every error (bad usage, a missing
or invalid run folder, SQL that does not parse or fails, a refused statement, an unreadable /
binary / non-SQL ``--file``, the memory or time limit hit), like the rest of the ``recap``
command; an error about a ``--file`` never quotes the file's text.

    recap report RUN_DIR [RUN_DIR ...] [--out DIR] [--format md,html,tex,csv]
                 [--episodes ID[,ID...]] [--viewer-max N] [--title TEXT] [--paper]
    recap sql RUN_DIR [RUN_DIR ...] "QUERY" [--csv | --json] [--max-rows N]
              [--memory-limit SIZE] [--timeout S]
    recap sql RUN_DIR [RUN_DIR ...] --file QUERY.sql
    recap sql RUN_DIR "@failure_modes"        # a report query from reports/sql/ by name

Options may come before, between or after the positional arguments (``parse_intermixed_args``);
``--help`` prints to stdout and returns 0. Which argument is what never depends on its text: in
``recap sql`` the last positional is the query (a URL in it is just text), the others are run
folders; in ``recap report`` every positional is a run folder.

``recap sql`` runs the query in a child process (:mod:`reports.sandbox`) stopped at
``--memory-limit`` (default 2GB of resident memory) or ``--timeout`` (default 60 s); the line
says which limit was hit. The report and ``recap view`` run only their own stored queries.
"""

from __future__ import annotations

import argparse
import logging
import math
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TextIO

import duckdb

from reports.build import FORMATS, ReportOptions, build_report, parse_formats, write_report
from reports.render_text import format_table as format_table
from reports.sandbox import DEFAULT_MEMORY, DEFAULT_TIMEOUT_S, Limits, parse_size, run_limited
from reports.viewer import DEFAULT_EPISODES
from reports.views import QueryError, ReportError, RunDirError, check_read_only, load_sql, resolve_run_dirs, sql_names

#: turns one run-folder argument into a local folder (the pipeline CLI pulls object-store runs)
Resolver = Callable[[str], str]

#: the longest --file read (a query, not a data file; also stops /dev/zero and the like)
MAX_QUERY_FILE_BYTES = 1 << 20

# the mains print skipped parts themselves ("warning: ..."); without a handler of the
# application's, Python's last-resort handler would print each a second time
logging.getLogger("reports").addHandler(logging.NullHandler())


class _Parser(argparse.ArgumentParser):
    """argparse that raises instead of exiting, so the mains can return a status; ``--help``
    prints to ``out`` (stdout by default) and ends the main with status 0."""

    def __init__(self, *args: Any, out: TextIO | None = None, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", argparse.RawDescriptionHelpFormatter)
        super().__init__(*args, **kwargs)
        self.out = out

    def error(self, message: str) -> None:  # type: ignore[override]
        raise _UsageError(f"{self.prog}: {message}")

    def exit(self, status: int = 0, message: str | None = None) -> None:  # type: ignore[override]
        if message:
            (self.out or sys.stdout).write(message)
        raise _Exit(status)

    def print_help(self, file: Any = None) -> None:
        (file or self.out or sys.stdout).write(self.format_help())

    def print_usage(self, file: Any = None) -> None:
        (file or self.out or sys.stdout).write(self.format_usage())


class _UsageError(Exception):
    pass


class OutputFolderError(ReportError):
    """The report's output folder holds files a report did not write (or is not a folder): refused, exit 2."""


class _Exit(Exception):
    """``--help`` was given: the help is printed, the main returns ``status``."""

    def __init__(self, status: int) -> None:
        super().__init__(status)
        self.status = status


_REPORT_EPILOG = """examples:
  recap report runs/demo                            all formats under runs/demo/report
  recap report runs/demo --format md,html --title "Demo sweep"
  recap report runs/a runs/b --out reports/ab       two runs in one report (--out required)
  recap report runs/demo --episodes 3f9c0a1b,77d2e0aa --format html
  recap report --viewer-max 0 runs/demo             options go before or after the run folders
  recap report runs/paper-main-robotouille runs/paper-main-alfworld --paper --out reports/paper
                                                    only the paper's tables (examples/paper/)

Writes only under the output folder (RUN_DIR/report or --out), and only into a new or empty
folder or one that holds an earlier report: a folder with any other file is refused.
exit status: 0 written; 1 a problem with the run folders' data or the option values; 2 bad usage,
a folder that is not a run folder (no run.json), or an output folder with other files in it
"""


def _report_parser(out: TextIO | None = None) -> _Parser:
    p = _Parser(
        prog="recap report",
        out=out,
        epilog=_REPORT_EPILOG,
        description="Write a report (Markdown, HTML, LaTeX, CSV) over one or more run folders.",
    )
    p.add_argument("run_dirs", nargs="+", metavar="RUN_DIR", help="run folder(s); several are reported together")
    p.add_argument("--out", metavar="DIR", help="output folder (default: RUN_DIR/report for one run; required for several)")
    p.add_argument(
        "--format",
        default=",".join(FORMATS),
        metavar="LIST",
        help=f"comma-separated formats among {','.join(FORMATS)} (default: all)",
    )
    p.add_argument("--episodes", metavar="IDS", help="comma-separated episode ids to show in the HTML viewer (default: a sample)")
    p.add_argument(
        "--viewer-max",
        type=int,
        default=DEFAULT_EPISODES,
        metavar="N",
        help=f"episodes in the viewer sample (default {DEFAULT_EPISODES}; 0 = none)",
    )
    p.add_argument("--title", default="recap-eval report", metavar="TEXT", help="report title (default: recap-eval report)")
    p.add_argument("--paper", action="store_true", help="only the paper section: the ReCAP paper's tables beside ours")
    return p


#: what a report folder may hold: the files and folders ``recap report`` writes (anything else is not ours)
_REPORT_FILES = {"report.md", "report.html"}
_REPORT_DIRS = {"plots": ".svg", "tex": ".tex", "csv": ".csv"}


def _foreign_entry(out_dir: Path) -> str | None:
    """The first entry of ``out_dir`` that a report did not write (a file of the user's, a run folder's
    run.json, a symlink), or None when the folder is missing, empty, or holds an earlier report only."""
    if not out_dir.exists() and not out_dir.is_symlink():
        return None
    if out_dir.is_symlink() or not out_dir.is_dir():
        return str(out_dir)
    for entry in sorted(out_dir.iterdir()):
        name = entry.name
        if name.startswith(".tmp-") and entry.is_file() and not entry.is_symlink():
            continue  # a write of an earlier report cut short
        if entry.is_symlink():
            return str(entry)
        if name in _REPORT_FILES and entry.is_file():
            continue
        if name in _REPORT_DIRS and entry.is_dir():
            for sub in sorted(entry.iterdir()):
                ours = sub.name.endswith(_REPORT_DIRS[name]) or sub.name.startswith(".tmp-")
                if sub.is_symlink() or not sub.is_file() or not ours:
                    return str(sub)
            continue
        return str(entry)
    return None


def check_report_folder(out_dir: Path) -> None:
    """Refuse (ReportError, one line) an output folder that holds anything a report did not write:
    the report replaces its own files only, never a file of someone else's."""
    foreign = _foreign_entry(out_dir)
    if foreign is None:
        return
    if foreign == str(out_dir):
        raise OutputFolderError(f"output folder {out_dir} is not a folder")
    raise OutputFolderError(
        f"output folder {out_dir} holds files a report did not write (such as {foreign}); give a new or empty folder with --out"
    )


def report_main(
    argv: Sequence[str],
    *,
    stdout: TextIO | None = None,
    stderr: TextIO | None = None,
    resolve_run: Resolver | None = None,
) -> int:
    """``recap report``: build and write the report (to RUN_DIR/report unless ``--out``); exit 0, 1 for a problem
    with the runs or options, 2 for bad usage and for a folder that is not a run folder.

    Writes only under the output folder, and only into a new or empty one or one that holds an earlier
    report (:func:`check_report_folder`); ``resolve_run`` makes each run-folder argument local."""
    out, err = stdout or sys.stdout, stderr or sys.stderr
    try:
        args = _report_parser(out).parse_intermixed_args(list(argv))
        formats = parse_formats(args.format)
        if args.viewer_max < 0:
            raise ReportError("--viewer-max must be >= 0")
        if args.out is None and len(args.run_dirs) > 1:
            raise ReportError("--out is required when reporting several run folders")
        if args.out is not None and "://" in args.out:
            raise _UsageError(f"recap report: --out must be a local folder, got {args.out}")
        run_dirs = _run_folders(args.run_dirs, resolve_run)
        out_dir = Path(args.out) if args.out else Path(run_dirs[0]) / "report"
        check_report_folder(out_dir)
        episodes = tuple(e.strip() for e in args.episodes.split(",") if e.strip()) if args.episodes else None
        options = ReportOptions(
            formats=formats, episodes=episodes, viewer_max=args.viewer_max, title=args.title, paper_only=args.paper
        )
        report = build_report(run_dirs, options)
        written = write_report(report, out_dir, formats)
    except _Exit as exc:
        return exc.status
    except _UsageError as exc:
        print(_one_line(str(exc)), file=err)
        return 2
    except (RunDirError, OutputFolderError) as exc:
        print(f"error: {exc}", file=err)
        return 2
    except ReportError as exc:
        print(f"error: {exc}", file=err)
        return 1
    except OSError as exc:
        print(_one_line(f"error: cannot write the report: {exc.strerror or type(exc).__name__}: {exc.filename or ''}"), file=err)
        return 1
    for s in report.skipped:
        print(f"warning: {s.line()}", file=err)
    print(f"wrote {len(written)} files to {out_dir} ({', '.join(formats)})", file=out)
    for name in ("report.html", "report.md"):
        if (out_dir / name).exists() and name.split(".")[1] in formats:
            print(f"  {out_dir / name}", file=out)
    return 0


_SQL_USAGE = """\
%(prog)s [-h] [--csv | --json] [--max-rows N] [--memory-limit SIZE] [--timeout S] RUN_DIR [RUN_DIR ...] QUERY
       %(prog)s [-h] [--csv | --json] [--max-rows N] [--memory-limit SIZE] [--timeout S] RUN_DIR [RUN_DIR ...] @NAME
       %(prog)s [-h] [--csv | --json] [--max-rows N] [--memory-limit SIZE] [--timeout S] --file QUERY.sql RUN_DIR [RUN_DIR ...]"""

_SQL_DESCRIPTION = """\
Run one read-only SQL query (DuckDB) over the tables and views of one or more run folders
(several folders are read as one set of tables; run_id tells them apart). The query is always
the last positional argument, whatever it holds (a URL, a path): SQL text, or @NAME for the
report query reports/sql/NAME.sql; with --file every positional argument is a run folder.
Anything but a query is refused. The query runs in its own process, stopped when it passes
--memory-limit (resident memory of that process) or --timeout (seconds since it started)."""


def _sql_epilog() -> str:
    import textwrap

    names = ", ".join(n for n in sql_names() if not n.startswith(("viewer_", "views", "macros")))
    names = textwrap.fill(f"named queries (@NAME): {names}", width=92, subsequent_indent="  ")
    return f"""\
examples:
  recap sql runs/demo "select arm, count(*) n, avg(success::int) ok from terminal group by 1"
  recap sql runs/demo --csv "select * from failures"    options go before or after the query
  recap sql runs/a runs/b "select run_id, count(*) from terminal group by 1" --json
  recap sql runs/demo @failure_modes                     a report query by name
  recap sql --file long_query.sql runs/a runs/b --max-rows 500
  recap sql runs/demo "select * from messages" --csv --memory-limit 8GB --timeout 600

{names}
tables: episodes, llm_calls, messages, tree_nodes, steps, events, run, bad_parts;
views: attempts, terminal, calls, nodes, tree_stats, step_patterns, episode_modes, failures

exit status: 0 ok; 2 any error (bad usage, a missing run folder, SQL that fails or is refused,
the memory or the time limit hit: the line says which)
"""


def _sql_size(text: str) -> int:
    try:
        return parse_size(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def finite_positive(text: str, what: str = "number") -> float:
    """argparse type: a finite number > 0 (``nan``, ``inf`` and ``-1`` are usage errors); ``what``
    names it in the message. The one rule for every such flag (``recap run --stop-grace`` too)."""
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid {what}: {text!r}") from None
    if not math.isfinite(x) or x <= 0:
        raise argparse.ArgumentTypeError(f"must be a finite {what} > 0, got {text!r}")
    return x


def _seconds(text: str) -> float:
    return finite_positive(text, "number of seconds")


def _sql_parser(out: TextIO | None = None) -> _Parser:
    p = _Parser(prog="recap sql", out=out, usage=_SQL_USAGE, description=_SQL_DESCRIPTION, epilog=_sql_epilog())
    p.add_argument(
        "args",
        nargs="+",
        metavar="RUN_DIR ... QUERY",
        help="run folder(s), then the query: SQL text or @NAME (reports/sql/NAME.sql)",
    )
    p.add_argument("--file", metavar="QUERY.sql", help="read the query from this file (then every positional is a run folder)")
    fmt = p.add_mutually_exclusive_group()
    fmt.add_argument("--csv", action="store_true", help="print CSV (every row)")
    fmt.add_argument("--json", action="store_true", help="print a JSON array of objects (every row)")
    p.add_argument("--max-rows", type=int, default=100, metavar="N", help="rows printed in table output (default 100)")
    p.add_argument(
        "--memory-limit",
        type=_sql_size,
        default=DEFAULT_MEMORY,
        metavar="SIZE",
        help=f"stop the query when its process holds more resident memory (default {DEFAULT_MEMORY}; at least 256MB; "
        "KB/MB/GB = 1000s, KiB/MiB/GiB = 1024s)",
    )
    p.add_argument(
        "--timeout",
        type=_seconds,
        default=DEFAULT_TIMEOUT_S,
        metavar="S",
        help=f"stop the query after this many seconds (default {DEFAULT_TIMEOUT_S:g})",
    )
    return p


def _memory_text(argv: Sequence[str]) -> str:
    """The --memory-limit as the user wrote it (the messages quote it), else the default."""
    text = DEFAULT_MEMORY
    for i, a in enumerate(argv):
        if a == "--memory-limit" and i + 1 < len(argv):
            text = argv[i + 1]
        elif a.startswith("--memory-limit="):
            text = a.split("=", 1)[1]
    return text.strip()


def _run_folders(raw: Sequence[str], resolve: Resolver | None) -> list[str]:
    """The run-folder arguments, each made local by ``resolve`` and checked (RunDirError, one line)."""
    local = [resolve(r) if resolve is not None else r for r in raw]
    resolve_run_dirs(local)
    return local


def _sql_positionals(args: argparse.Namespace) -> tuple[list[str], str]:
    """(run-folder arguments, query): the last positional is the query unless --file gives it."""
    if args.file:
        return list(args.args), _read_query_file(args.file)
    if len(args.args) < 2:
        raise _UsageError("recap sql: give at least one RUN_DIR and a QUERY")
    run_dirs, query = list(args.args[:-1]), args.args[-1]
    for r in run_dirs:
        if any(c.isspace() for c in r) and not Path(r).exists():
            raise _UsageError(
                f"recap sql: {_one_line(r)[:60]!r} is not a folder; the query comes last: recap sql RUN_DIR ... QUERY"
            )
    if query.startswith("@"):
        query = load_sql(query[1:])
    return run_dirs, query


def sql_main(
    argv: Sequence[str],
    *,
    stdout: TextIO | None = None,
    stderr: TextIO | None = None,
    resolve_run: Resolver | None = None,
) -> int:
    """``recap sql``: run one query (text, ``@name`` of a stored query, or ``--file``) over the runs and print a
    table, CSV or JSON; every error is one line and exit status 2.

    The query runs in a child process (:mod:`reports.sandbox`) under ``--memory-limit`` and ``--timeout``;
    arguments, run folders and the read-only check are settled here first. ``resolve_run`` makes each
    run-folder argument local (the pipeline CLI pulls object-store runs); it is never given the query."""
    out, err = stdout or sys.stdout, stderr or sys.stderr
    try:
        args = _sql_parser(out).parse_intermixed_args(list(argv))
        run_dirs, query = _sql_positionals(args)
        run_dirs = _run_folders(run_dirs, resolve_run)
        if args.file:
            _check_query_file(args.file, query)
        con = duckdb.connect(":memory:")
        try:
            check_read_only(con, query)
        except QueryError:
            if not args.file and query.strip() and Path(query).is_dir():  # recap sql RUN_A RUN_B, no query
                raise _UsageError(
                    f"recap sql: the last argument is the query, but {query} is a folder; add the QUERY after the run folders"
                ) from None
            raise
        finally:
            con.close()
        limits = Limits(memory_bytes=args.memory_limit, timeout_s=args.timeout, memory_text=_memory_text(argv))
        fmt = "csv" if args.csv else "json" if args.json else "table"
        # absolute: the query process must not depend on the working folder
        job = {"run_dirs": [str(d) for d in resolve_run_dirs(run_dirs)], "query": query, "format": fmt, "max_rows": args.max_rows}
        return run_limited(job, limits, out, err).status
    except KeyboardInterrupt:  # the query process is gone with it (run_limited)
        print("recap sql: interrupted", file=err)
        return 130
    except _Exit as exc:
        return exc.status
    except _UsageError as exc:
        print(_one_line(str(exc)), file=err)
        return 2
    except ReportError as exc:
        print(f"error: {exc}", file=err)
        return 2
    except Exception as exc:  # noqa: BLE001 - the contract is one line and status 2, never a traceback
        print(_one_line(f"error: {type(exc).__name__}: {_strip_context(str(exc))}"), file=err)
        return 2


def _read_query_file(path: str) -> str:
    """The text of a --file query; errors name the file and never quote what is in it."""
    try:
        with open(path, "rb") as fh:
            data = fh.read(MAX_QUERY_FILE_BYTES + 1)
    except OSError as exc:
        raise ReportError(f"cannot read query file {path}: {exc.strerror or type(exc).__name__}") from None
    if len(data) > MAX_QUERY_FILE_BYTES:
        raise ReportError(f"query file {path} is larger than {MAX_QUERY_FILE_BYTES // 1024} KiB; is it a query?")
    if b"\0" in data:
        raise ReportError(f"query file {path} is not a text file (it holds NUL bytes)")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ReportError(f"query file {path} is not UTF-8 text (invalid byte at offset {exc.start})") from None
    return text.removeprefix("\ufeff")


_LINE = re.compile(r"\bLINE (\d+):")
_CONTEXT = re.compile(r"\n\s*LINE \d+:.*", re.DOTALL)


def _strip_context(message: str) -> str:
    """DuckDB's message without the ``LINE n: <query text>`` context it appends."""
    return _CONTEXT.sub("", message)


def _check_query_file(path: str, text: str) -> None:
    """A --file must parse as SQL; the error says where, never what (the file may be anything)."""
    con = duckdb.connect(":memory:")
    try:
        statements = con.extract_statements(text)
    except Exception as exc:  # noqa: BLE001 - any parser complaint
        line = _LINE.search(str(exc))
        where = f" (syntax error on line {line.group(1)})" if line else ""
        raise ReportError(f"query file {path} is not valid SQL{where}") from None
    finally:
        con.close()
    if not statements:
        raise ReportError(f"query file {path} holds no SQL statement")


def _one_line(text: str) -> str:
    return " ".join(text.split())


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m reports.commands report|sql ...`` (the pipeline CLI calls the two mains)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] not in ("report", "sql"):
        print("usage: python -m reports.commands {report,sql} ...", file=sys.stderr)
        return 2
    return (report_main if argv[0] == "report" else sql_main)(argv[1:])


if __name__ == "__main__":
    raise SystemExit(main())
