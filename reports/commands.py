"""``recap report`` and ``recap sql``: the command-line faces of the reports package.

The pipeline CLI hands its remaining arguments to :func:`report_main` or :func:`sql_main`; both
return an exit status and print one-line errors, never tracebacks. ``recap report``: 0 ok, 1 a
problem with the runs or the options, 2 bad usage. ``recap sql``: 0 ok, 2 for every error (bad
usage, a missing or invalid run folder, SQL that does not parse or fails, a refused statement,
an unreadable / binary / non-SQL ``--file``), like the rest of the ``recap`` command; an error
about a ``--file`` never quotes the file's text.

    recap report RUN_DIR [RUN_DIR ...] [--out DIR] [--format md,html,tex,csv]
                 [--episodes ID[,ID...]] [--viewer-max N] [--title TEXT] [--paper]
    recap sql RUN_DIR [RUN_DIR ...] "QUERY" [--csv | --json] [--max-rows N]
    recap sql RUN_DIR [RUN_DIR ...] --file QUERY.sql
    recap sql RUN_DIR "@failure_modes"        # a report query from reports/sql/ by name

Options may come before, between or after the positional arguments (``parse_intermixed_args``);
``--help`` prints to stdout and returns 0.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import re
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO

import duckdb

from reports.build import FORMATS, ReportOptions, build_report, parse_formats, write_report
from reports.render_csv import result_csv
from reports.viewer import DEFAULT_EPISODES
from reports.views import ReportError, Result, load_sql, open_runs_checked, run_query, sql_names

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
  recap report runs/paper-main runs/paper-main-x3 --paper --out reports/paper
                                                    only the paper's tables (examples/paper/)

exit status: 0 written; 1 a problem with the run folders or the option values; 2 bad usage
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


def report_main(argv: Sequence[str], *, stdout: TextIO | None = None, stderr: TextIO | None = None) -> int:
    """``recap report``: build and write the report (to RUN_DIR/report unless ``--out``); exit 0, 1 for a problem
    with the runs or options, 2 for bad usage."""
    out, err = stdout or sys.stdout, stderr or sys.stderr
    try:
        args = _report_parser(out).parse_intermixed_args(list(argv))
        formats = parse_formats(args.format)
        if args.viewer_max < 0:
            raise ReportError("--viewer-max must be >= 0")
        if args.out is None and len(args.run_dirs) > 1:
            raise ReportError("--out is required when reporting several run folders")
        episodes = tuple(e.strip() for e in args.episodes.split(",") if e.strip()) if args.episodes else None
        options = ReportOptions(
            formats=formats, episodes=episodes, viewer_max=args.viewer_max, title=args.title, paper_only=args.paper
        )
        report = build_report(args.run_dirs, options)
        out_dir = Path(args.out) if args.out else Path(args.run_dirs[0]) / "report"
        written = write_report(report, out_dir, formats)
    except _Exit as exc:
        return exc.status
    except _UsageError as exc:
        print(_one_line(str(exc)), file=err)
        return 2
    except ReportError as exc:
        print(f"error: {exc}", file=err)
        return 1
    for s in report.skipped:
        print(f"warning: {s.line()}", file=err)
    print(f"wrote {len(written)} files to {out_dir} ({', '.join(formats)})", file=out)
    for name in ("report.html", "report.md"):
        if (out_dir / name).exists() and name.split(".")[1] in formats:
            print(f"  {out_dir / name}", file=out)
    return 0


_SQL_USAGE = """\
%(prog)s [-h] [--csv | --json] [--max-rows N] RUN_DIR [RUN_DIR ...] QUERY
       %(prog)s [-h] [--csv | --json] [--max-rows N] RUN_DIR [RUN_DIR ...] @NAME
       %(prog)s [-h] [--csv | --json] [--max-rows N] --file QUERY.sql RUN_DIR [RUN_DIR ...]"""

_SQL_DESCRIPTION = """\
Run one read-only SQL query (DuckDB) over the tables and views of one or more run folders
(several folders are read as one set of tables; run_id tells them apart). The query is the
last positional argument: SQL text, or @NAME for the report query reports/sql/NAME.sql; with
--file every positional argument is a run folder. Anything but a query is refused."""


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

{names}
tables: episodes, llm_calls, messages, tree_nodes, steps, events, run, bad_parts;
views: attempts, terminal, calls, nodes, tree_stats, step_patterns, episode_modes, failures

exit status: 0 ok; 2 any error (bad usage, a missing run folder, SQL that fails or is refused)
"""


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
    return p


def sql_main(argv: Sequence[str], *, stdout: TextIO | None = None, stderr: TextIO | None = None) -> int:
    """``recap sql``: run one query (text, ``@name`` of a stored query, or ``--file``) over the runs and print a
    table, CSV or JSON; every error is one line and exit status 2."""
    out, err = stdout or sys.stdout, stderr or sys.stderr
    try:
        args = _sql_parser(out).parse_intermixed_args(list(argv))
        if args.file:
            run_dirs, query = args.args, _read_query_file(args.file)
            _check_query_file(args.file, query)
        else:
            if len(args.args) < 2:
                raise _UsageError("recap sql: give at least one RUN_DIR and a QUERY")
            run_dirs, query = args.args[:-1], args.args[-1]
            if query.startswith("@"):
                query = load_sql(query[1:])
        con, skipped = open_runs_checked(run_dirs)
        try:
            result = run_query(con, query)
        finally:
            con.close()
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
    for s in skipped:
        print(f"warning: {s.line()}", file=err)
    if args.csv:
        out.write(result_csv(result))
    elif args.json:
        out.write(
            json.dumps([{k: _json_value(v) for k, v in zip(result.columns, r)} for r in result.rows], indent=1, default=str)
            + "\n"
        )
    else:
        out.write(format_table(result, max_rows=args.max_rows))
    return 0


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


def _json_value(v: Any) -> Any:
    if isinstance(v, float) and (math.isnan(v) or math.isinf(v)):
        return None
    if isinstance(v, tuple):
        return list(v)
    return v


def _text(v: Any, width: int) -> str:
    if v is None:
        s = "NULL"
    elif isinstance(v, float):
        s = f"{v:.6g}"
    else:
        s = str(v)
    s = " ".join(s.split()) if "\n" in s else s
    return s if len(s) <= width else s[: width - 1] + "…"


def format_table(result: Result, *, max_rows: int = 100, width: int = 60) -> str:
    """An aligned text table, numbers right-aligned, at most ``max_rows`` rows."""
    shown = result.rows[: max(max_rows, 0)]
    cells = [[_text(v, width) for v in row] for row in shown]

    def is_number(v: Any) -> bool:
        return isinstance(v, (int, float)) and not isinstance(v, bool)

    numeric = [
        any(r[i] is not None for r in shown) and all(is_number(r[i]) for r in shown if r[i] is not None)
        for i in range(len(result.columns))
    ]
    widths = [max([len(c)] + [len(row[i]) for row in cells]) for i, c in enumerate(result.columns)]

    def line(values: list[str]) -> str:
        return " | ".join(v.rjust(w) if numeric[i] else v.ljust(w) for i, (v, w) in enumerate(zip(values, widths))).rstrip()

    lines = [line(list(result.columns)), "-+-".join("-" * w for w in widths)]
    lines += [line(row) for row in cells]
    n = len(result.rows)
    more = n - len(shown)
    lines.append(
        f"({n} row{'s' if n != 1 else ''}" + (f"; {more} not shown, use --max-rows, --csv or --json)" if more > 0 else ")")
    )
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m reports.commands report|sql ...`` (the pipeline CLI calls the two mains)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] not in ("report", "sql"):
        print("usage: python -m reports.commands {report,sql} ...", file=sys.stderr)
        return 2
    return (report_main if argv[0] == "report" else sql_main)(argv[1:])


if __name__ == "__main__":
    raise SystemExit(main())
