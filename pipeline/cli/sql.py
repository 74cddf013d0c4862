"""``recap sql RUN_DIR ... QUERY``: one read-only query over run folders' tables, in a child process with limits.

Every error is one line and exit status 2 (bad usage, a missing or invalid run folder, SQL that
does not parse or fails, a refused statement, an unreadable / binary / non-SQL ``--file``, the
memory or time limit hit), like the rest of the ``recap`` command; an error about a ``--file``
never quotes the file's text.

    recap sql RUN_DIR [RUN_DIR ...] "QUERY" [--csv | --json] [--max-rows N]
              [--memory-limit SIZE] [--timeout S]
    recap sql RUN_DIR [RUN_DIR ...] --file QUERY.sql
    recap sql RUN_DIR "@failure_modes"        # a report query from reports/sql/ by name

Options may come before, between or after the positional arguments (``parse_intermixed_args``);
which argument is what never depends on its text: the last positional is the query (a URL in it
is just text), the others are run folders. The query runs in a child process
(:mod:`reports.sandbox`) stopped at ``--memory-limit`` (default 2GB of resident memory) or
``--timeout`` (default 60 s); the line says which limit was hit.
"""

from __future__ import annotations

import argparse
import re
import sys
import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import TextIO

import duckdb

from pipeline.cli.common import EXIT_USAGE, CommandParser, HelpExit, UsageError, error_line, seconds
from pipeline.cli.locations import Resolver, local_run_dir, run_folders
from pipeline.errors import one_line
from reports.sandbox import DEFAULT_MEMORY, DEFAULT_TIMEOUT_S, Limits, parse_size, run_limited
from reports.views import QueryError, ReportError, check_read_only, load_sql, resolve_run_dirs, sql_names

#: the longest --file read (a query, not a data file; also stops /dev/zero and the like)
MAX_QUERY_FILE_BYTES = 1 << 20

_USAGE = """\
%(prog)s [-h] [--csv | --json] [--max-rows N] [--memory-limit SIZE] [--timeout S] RUN_DIR [RUN_DIR ...] QUERY
       %(prog)s [-h] [--csv | --json] [--max-rows N] [--memory-limit SIZE] [--timeout S] RUN_DIR [RUN_DIR ...] @NAME
       %(prog)s [-h] [--csv | --json] [--max-rows N] [--memory-limit SIZE] [--timeout S] --file QUERY.sql RUN_DIR [RUN_DIR ...]"""

_DESCRIPTION = """\
Run one read-only SQL query (DuckDB) over the tables and views of one or more run folders
(several folders are read as one set of tables; run_id tells them apart). The query is always
the last positional argument, whatever it holds (a URL, a path): SQL text, or @NAME for the
report query reports/sql/NAME.sql; with --file every positional argument is a run folder.
Anything but a query is refused. The query runs in its own process, stopped when it passes
--memory-limit (resident memory of that process) or --timeout (seconds since it started)."""


def _epilog() -> str:
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
tables: episodes, llm_calls, messages, tree_nodes, steps, tool_calls, events, run, bad_parts,
  wiki_requests, wiki_pages (FEVER: each page body once per run; wiki_pages_raw: the rows as
  written), evaluations (SWE-bench: each judged submission);
views: attempts, terminal, calls, nodes, tree_stats, step_patterns, tool_stats, episode_modes,
  failures

exit status: 0 ok; 2 any error (bad usage, a missing run folder, SQL that fails or is refused,
the memory or the time limit hit: the line says which)
"""


def _size(text: str) -> int:
    try:
        return parse_size(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def parser(out: TextIO | None = None) -> CommandParser:
    """The ``recap sql`` parser (``out``: where ``--help`` goes)."""
    p = CommandParser(prog="recap sql", out=out, usage=_USAGE, description=_DESCRIPTION, epilog=_epilog())
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
        type=_size,
        default=DEFAULT_MEMORY,
        metavar="SIZE",
        help=f"stop the query when its process holds more resident memory (default {DEFAULT_MEMORY}; at least 256MB; "
        "KB/MB/GB = 1000s, KiB/MiB/GiB = 1024s)",
    )
    p.add_argument(
        "--timeout",
        type=seconds,
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


def _positionals(args: argparse.Namespace) -> tuple[list[str], str]:
    """(run-folder arguments, query): the last positional is the query unless --file gives it."""
    if args.file:
        return list(args.args), _read_query_file(args.file)
    if len(args.args) < 2:
        raise UsageError("recap sql: give at least one RUN_DIR and a QUERY")
    run_dirs, query = list(args.args[:-1]), args.args[-1]
    for r in run_dirs:
        if any(c.isspace() for c in r) and not Path(r).exists():
            raise UsageError(
                f"recap sql: {one_line(r)[:60]!r} is not a folder; the query comes last: recap sql RUN_DIR ... QUERY"
            )
    if query.startswith("@"):
        query = load_sql(query[1:])
    return run_dirs, query


def _check_read_only(query: str, from_file: bool) -> None:
    """Refuse anything but a read-only query (QueryError), or the last run folder given where the query goes."""
    con = duckdb.connect(":memory:")
    try:
        check_read_only(con, query)
    except QueryError:
        if not from_file and query.strip() and Path(query).is_dir():  # recap sql RUN_A RUN_B, no query
            raise UsageError(
                f"recap sql: the last argument is the query, but {query} is a folder; add the QUERY after the run folders"
            ) from None
        raise
    finally:
        con.close()


def _run(argv: Sequence[str], out: TextIO, err: TextIO, resolve_run: Resolver | None) -> int:
    """Settle the arguments, the run folders and the read-only check, then run the query under its limits."""
    args = parser(out).parse_intermixed_args(list(argv))
    run_dirs, query = _positionals(args)
    run_dirs = run_folders(run_dirs, resolve_run)
    if args.file:
        _check_query_file(args.file, query)
    _check_read_only(query, bool(args.file))
    limits = Limits(memory_bytes=args.memory_limit, timeout_s=args.timeout, memory_text=_memory_text(argv))
    fmt = "csv" if args.csv else "json" if args.json else "table"
    # absolute: the query process must not depend on the working folder
    job = {"run_dirs": [str(d) for d in resolve_run_dirs(run_dirs)], "query": query, "format": fmt, "max_rows": args.max_rows}
    return run_limited(job, limits, out, err).status


def sql_main(
    argv: Sequence[str],
    *,
    stdout: TextIO | None = None,
    stderr: TextIO | None = None,
    resolve_run: Resolver | None = None,
) -> int:
    """``recap sql``: run one query (text, ``@name`` of a stored query, or ``--file``) over the runs and print a
    table, CSV or JSON; every error is one line and exit status 2.

    ``resolve_run`` makes each run-folder argument local (:func:`main` pulls object-store runs); it is
    never given the query."""
    out, err = stdout or sys.stdout, stderr or sys.stderr
    try:
        return _run(argv, out, err, resolve_run)
    except KeyboardInterrupt:  # the query process is gone with it (run_limited)
        print("recap sql: interrupted", file=err)
        return 130
    except HelpExit as exc:
        return exc.status
    except UsageError as exc:
        print(error_line("sql", exc), file=err)
        return EXIT_USAGE
    except ReportError as exc:
        print(error_line("sql", exc), file=err)
        return EXIT_USAGE
    except Exception as exc:  # noqa: BLE001 - the contract is one line and status 2, never a traceback
        print(error_line("sql", f"{type(exc).__name__}: {_strip_context(str(exc))}"), file=err)
        return EXIT_USAGE


def main(argv: list[str]) -> int:
    """``recap sql ...``: object-store run folders are pulled to a local copy first."""
    return sql_main(argv, resolve_run=local_run_dir)


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
