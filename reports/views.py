"""One read-only DuckDB connection over the Parquet tables of one or several run folders.

Why this shape: every number in a report is a SQL query kept in ``reports/sql/``, and the same
views answer ad-hoc questions (``recap sql``). The tables of all given runs are unioned into one
view each (``episodes``, ``llm_calls``, ``messages``, ``tree_nodes``, ``steps``, ``tool_calls``, ``events``,
``run``), and ``reports/sql/views.sql`` adds short named views on top (``attempts``,
``terminal``, ``calls``, ``nodes``, ``tree_stats``, ``failures``, ...).

Read-only comes from how the data is opened, not from a list of refused statements:

* the part files are opened by pyarrow (a ``pyarrow.dataset`` per table, read lazily with
  projection and filter pushdown) and handed to DuckDB as Arrow streams, so DuckDB itself never
  holds a path to any part file. Once the views exist DuckDB's file access is switched off
  entirely (``enable_external_access = false`` with no allowed path or folder), extension
  install/load is off and the configuration is locked (``lock_configuration``), so no statement
  can reach any file: ``COPY ... TO``, ``EXPORT``, ``ATTACH``, ``INSTALL``, ``read_csv('/etc/...')``,
  ``SET`` (including turning access back on) and profiling output all fail. There is no spill
  folder either (DuckDB would let statements write there), so a query bigger than memory fails;
* on top, every statement that goes through :func:`run_query` (``recap sql``, the report) is
  parsed first and anything that is not a query is refused with a one-line
  :class:`ReadOnlyError`; ``EXPLAIN`` / ``EXPLAIN ANALYZE`` are parsed too and allowed only
  around a query (``EXPLAIN ANALYZE`` runs its statement).

Part files that are broken (truncated, corrupt footer) or do not match their table's Arrow
schema in ``schemas/`` (a missing column, a column of another type) are found with
:func:`schemas.parts.check_parts` - the same rule ``recap status`` applies - skipped, logged,
and listed in the ``bad_parts`` table. Parts of an earlier schema version are mapped to the
current one (:mod:`schemas.versions`) as every reader maps them. A table without good files is an empty view with the
table's full schema.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import duckdb
import pyarrow as pa
import pyarrow.dataset as ds
import pyarrow.parquet as pq

from schemas.parts import RUN_FILE, check_parts, read_part, read_run_file
from schemas.tables import TABLES, UNIQUE_BY

log = logging.getLogger(__name__)

SQL_DIR = Path(__file__).resolve().with_name("sql")

#: PRAGMAs that only read (the others set options or import databases)
_READ_PRAGMAS = {
    "table_info",
    "show",
    "show_tables",
    "show_tables_expanded",
    "show_databases",
    "database_list",
    "database_size",
    "storage_info",
    "metadata_info",
    "version",
    "platform",
    "functions",
    "collations",
    "user_agent",
}


class ReportError(Exception):
    """A user-facing problem with a run folder, a query or report options (one-line message)."""

    def __init__(self, message: str) -> None:
        super().__init__(" ".join(str(message).split()))


class RunDirError(ReportError):
    """A path given as a run folder is missing or is not a run folder."""


class ReadOnlyError(ReportError):
    """A statement that could change something was sent to the read-only connection."""


class QueryError(ReportError):
    """A query failed to parse or to run."""


@dataclass(frozen=True)
class SkippedPart:
    """A part file left out of the views because it cannot be read."""

    run_dir: str
    table: str
    path: str
    error: str

    def line(self) -> str:
        """The one-line warning the report and ``recap sql`` print for a skipped part file."""
        return f"skipped unreadable part file {self.path} ({self.table}): {self.error}"


# -- opening runs ------------------------------------------------------------------------------


def resolve_run_dirs(run_dirs: Sequence[str | Path]) -> list[Path]:
    """The run folders as absolute paths, each once; RunDirError (one line) for a missing folder or one without run.json."""
    if isinstance(run_dirs, (str, Path)):
        run_dirs = [run_dirs]
    if not run_dirs:
        raise RunDirError("no run folder given")
    out: list[Path] = []
    for raw in run_dirs:
        p = Path(raw).expanduser().resolve()
        if not p.is_dir():
            raise RunDirError(f"run folder {raw} does not exist or is not a folder")
        # the rule of recap status and resume: a run folder has its run.json (table folders alone
        # are not enough; the report would write its files into any folder that had one)
        if not (p / RUN_FILE).is_file():
            raise RunDirError(f"{raw} is not a run folder (no {RUN_FILE})")
        if read_run_file(p) is None:
            raise RunDirError(f"{raw} is not a run folder (its {RUN_FILE} is unreadable or not a JSON object)")
        if p not in out:
            out.append(p)
    return out


def _run_identity(run_dir: Path) -> str | None:
    """The run id from run.json when it has one (the pipeline writes it once per run)."""
    rid = (read_run_file(run_dir) or {}).get("run_id")
    return str(rid) if rid is not None else None


def scan_runs(run_dirs: Sequence[str | Path]) -> tuple[list[Path], dict[str, list[Path]], list[SkippedPart]]:
    """Readable part files per table over all runs, and the broken ones."""
    dirs = resolve_run_dirs(run_dirs)
    files: dict[str, list[Path]] = {t: [] for t in TABLES}
    skipped: list[SkippedPart] = []
    for d in dirs:
        for table in TABLES:
            good, bad = check_parts(d, table)
            files[table].extend(good)
            skipped.extend(SkippedPart(str(d), table, str(b.path), b.error) for b in bad)
    return dirs, files, skipped


@cache
def duckdb_types() -> dict[str, dict[str, str]]:
    """DuckDB's type for every column of every table, from the Arrow schemas."""
    con = duckdb.connect(":memory:")
    out: dict[str, dict[str, str]] = {}
    for table, schema in TABLES.items():
        empty = schema.empty_table()  # noqa: F841 - read by DuckDB's replacement scan below
        out[table] = {
            name: typ
            for name, typ in con.execute("SELECT column_name, column_type FROM (DESCRIBE SELECT * FROM empty)").fetchall()
        }
    con.close()
    return out


def _create_table_view(con: duckdb.DuckDBPyConnection, table: str, files: list[Path]) -> None:
    """View ``table`` over ``files`` with exactly the declared columns and types.

    The files are read by pyarrow (DuckDB scans the dataset as Arrow, pushing projections and
    filters down) so that DuckDB's own file access can be switched off completely.
    """
    schema = TABLES[table]
    current = [f for f in files if set(schema.names) <= set(pq.read_schema(f).names)]
    older = [f for f in files if f not in current]
    source: Any = ds.dataset([str(f) for f in current], schema=schema, format="parquet") if current else schema.empty_table()
    con.register(f"_parts_{table}", source)
    cols = ", ".join(f'"{c}"' for c in schema.names)
    body = f'SELECT {cols} FROM "_parts_{table}"'
    if older:
        # parts of an earlier schema version, mapped to the current one (schemas.versions): read
        # into memory here, since their rows need more than a projection
        con.register(f"_older_{table}", pa.concat_tables([read_part(str(f), table) for f in older]))
        body += f' UNION ALL SELECT {cols} FROM "_older_{table}"'
    key = UNIQUE_BY.get(table)
    if key is None:
        con.execute(f'CREATE VIEW "{table}" AS {body}')
        return
    # a content-addressed table (wiki_pages): the rows as written stay queryable as <table>_raw,
    # the table's own name keeps one row per key (rows with one key hold the same bytes)
    con.execute(f'CREATE VIEW "{table}_raw" AS {body}')
    on = ", ".join(f'"{c}"' for c in key)
    con.execute(f'CREATE VIEW "{table}" AS SELECT DISTINCT ON ({on}) {cols} FROM "{table}_raw"')


def open_runs(run_dirs: Sequence[str | Path], *, read_only: bool = True) -> duckdb.DuckDBPyConnection:
    """An in-memory DuckDB with a view per table over the readable parts of all ``run_dirs``.

    Unreadable part files are skipped (logged as warnings, listed in ``bad_parts``).
    ``read_only=False`` leaves DuckDB's file access on (for callers that export on purpose).
    """
    con, _ = open_runs_checked(run_dirs, read_only=read_only)
    return con


def open_runs_checked(
    run_dirs: Sequence[str | Path],
    *,
    read_only: bool = True,
    memory_limit: str | None = None,
    threads: int | None = None,
) -> tuple[duckdb.DuckDBPyConnection, list[SkippedPart]]:
    """:func:`open_runs` that also returns the skipped part files.

    ``read_only=False`` leaves DuckDB's file access and configuration as they are (a caller that
    exports on purpose); the part files are still read through pyarrow, never opened by DuckDB.
    ``memory_limit`` (DuckDB's syntax, e.g. ``'1GB'``) and ``threads`` are set before the
    configuration is locked, so no query can raise them (``recap sql``'s child process).
    """
    dirs, files, skipped = scan_runs(run_dirs)
    for s in skipped:
        # info, not warning: the caller gets the skipped parts back and reports them (recap sql,
        # report and status print one warning line each; a second copy from logging would double it)
        log.info(s.line())
    con = duckdb.connect(":memory:")
    if memory_limit is not None:
        if not re.fullmatch(r"[0-9]+(\.[0-9]+)?[A-Za-z]+", memory_limit):
            raise ValueError(f"memory_limit: expected a size such as 1GB, got {memory_limit!r}")
        con.execute(f"SET memory_limit = '{memory_limit}'")
    if threads is not None:
        con.execute(f"SET threads = {int(threads)}")
    for table, parts in files.items():
        _create_table_view(con, table, parts)
    con.execute('CREATE TABLE bad_parts (run_dir VARCHAR, "table" VARCHAR, path VARCHAR, error VARCHAR)')
    if skipped:
        con.executemany("INSERT INTO bad_parts VALUES (?, ?, ?, ?)", [(s.run_dir, s.table, s.path, s.error) for s in skipped])
    con.execute("CREATE TABLE run_dirs (run_dir VARCHAR, run_json_id VARCHAR, part_files BIGINT)")
    con.executemany(
        "INSERT INTO run_dirs VALUES (?, ?, ?)",
        [(str(d), _run_identity(d), sum(1 for fs in files.values() for f in fs if f.is_relative_to(d))) for d in dirs],
    )
    for statement in split_statements(load_sql("macros")) + split_statements(load_sql("views")):
        con.execute(statement)
    if read_only:
        _lock_down(con)
    return con, skipped


def _lock_down(con: duckdb.DuckDBPyConnection) -> None:
    """No file reachable from ``con`` from now on, for reading or writing, and no way back."""
    # no spill folder: DuckDB would add it to the folders statements may write to (and its
    # default, '.tmp' in the working folder, may be inside a run folder); a query bigger than
    # memory fails instead
    con.execute("SET temp_directory = ''")
    con.execute("SET enable_progress_bar = false")  # not on a pipe to a relaying parent either
    con.execute("SET allowed_paths = []")
    con.execute("SET allowed_directories = []")
    con.execute("SET enable_external_access = false")
    con.execute("SET autoinstall_known_extensions = false")
    con.execute("SET autoload_known_extensions = false")
    con.execute("SET allow_community_extensions = false")
    con.execute("SET python_enable_replacements = false")
    con.execute("SET lock_configuration = true")


def materialize(con: duckdb.DuckDBPyConnection, names: Sequence[str]) -> None:
    """Compute the named views once and read them from memory from now on.

    For a report that queries the same derived view many times (``attempts``,
    ``episode_modes``): the view is replaced by one over an in-memory copy; views built on it
    pick the copy up because DuckDB binds views by name when a query runs. Nothing is written
    to the run folders.
    """
    for name in names:
        con.execute(f'CREATE TEMP TABLE "_mat_{name}" AS SELECT * FROM "{name}"')
        con.execute(f'CREATE OR REPLACE VIEW "{name}" AS SELECT * FROM temp."_mat_{name}"')


# -- SQL files -----------------------------------------------------------------------------------


@cache
def load_sql(name: str) -> str:
    """The text of ``reports/sql/<name>.sql``."""
    path = SQL_DIR / f"{name}.sql"
    if not path.is_file():
        known = ", ".join(sorted(p.stem for p in SQL_DIR.glob("*.sql")))
        raise ReportError(f"no report query named {name!r}; known: {known}")
    return path.read_text()


def sql_names() -> list[str]:
    """Names of the stored queries (the ``reports/sql/*.sql`` files), sorted: what ``@name`` and the report can run."""
    return sorted(p.stem for p in SQL_DIR.glob("*.sql"))


_COMMENT = re.compile(r"--[^\n]*")


def split_statements(text: str) -> list[str]:
    """Split a SQL file on ``;`` at line ends (our files never put ``;`` inside strings)."""
    body = _COMMENT.sub("", text)
    return [s.strip() for s in re.split(r";\s*(?:\n|$)", body) if s.strip()]


# -- read-only queries ---------------------------------------------------------------------------


_ALLOWED = "allowed: SELECT, WITH, DESCRIBE, SHOW, SUMMARIZE, EXPLAIN, read-only PRAGMA"
_COMMENT_TOKEN = duckdb.token_type.comment


def _tokens(text: str) -> list[tuple[int, str, Any]]:
    """(start, text, kind) of every token of ``text`` except comments."""
    raw = duckdb.tokenize(text)
    out = []
    for i, (start, kind) in enumerate(raw):
        end = raw[i + 1][0] if i + 1 < len(raw) else len(text)
        if kind != _COMMENT_TOKEN:
            out.append((start, text[start:end].strip(), kind))
    return out


def _words(tokens: list[tuple[int, str, Any]], i: int) -> str:
    return tokens[i][1].lower() if i < len(tokens) else ""


def _explained(con: duckdb.DuckDBPyConnection, text: str) -> Any | None:
    """The one statement inside ``EXPLAIN [ANALYZE] [VERBOSE] [(options)] <statement>``, or None
    when it cannot be told exactly (then the EXPLAIN is refused)."""
    try:
        toks = _tokens(text)
    except Exception:  # noqa: BLE001 - the tokenizer refusing the text: refuse the statement
        return None
    if _words(toks, 0) != "explain":
        return None
    i = 1
    if _words(toks, i) in ("analyze", "analyse"):
        i += 1
    if _words(toks, i) == "verbose":
        i += 1
    if i >= len(toks):
        return None
    starts = [toks[i][0]]
    if toks[i][2] == duckdb.token_type.operator and toks[i][1].startswith("("):
        depth, j = 0, i
        while j < len(toks):
            if toks[j][2] == duckdb.token_type.operator:
                depth += toks[j][1].count("(") - toks[j][1].count(")")
                if depth <= 0:
                    break
            j += 1
        if depth == 0 and j + 1 < len(toks) and toks[j][1].endswith(")"):
            starts.append(toks[j + 1][0])
    for start in starts:
        try:
            inner = con.extract_statements(text[start:])
        except duckdb.Error:
            continue
        if len(inner) == 1:
            return inner[0]
    return None


def _refuse(kind: str) -> ReadOnlyError:
    return ReadOnlyError(f"refused {kind} statement: reports are read-only ({_ALLOWED})")


def check_read_only(con: duckdb.DuckDBPyConnection, sql: str) -> int:
    """Raise :class:`ReadOnlyError` unless every statement in ``sql`` only reads.

    Returns the number of statements. Allowed: SELECT/WITH/VALUES/FROM, DESCRIBE, SHOW,
    SUMMARIZE, the read-only PRAGMAs, and EXPLAIN / EXPLAIN ANALYZE of a query (EXPLAIN ANALYZE
    runs its statement, so what it explains is checked like a statement of its own). This is
    the second line of defence: the connection from :func:`open_runs` cannot reach any file.
    """
    try:
        statements = con.extract_statements(sql)
    except duckdb.Error as exc:
        raise QueryError(f"cannot parse query: {_first_line(exc)}") from None
    if not statements:
        raise QueryError("empty query")
    for st in statements:
        if st.type == duckdb.StatementType.SELECT:
            continue
        if st.type == duckdb.StatementType.EXPLAIN:
            inner = _explained(con, st.query)
            if inner is not None and inner.type == duckdb.StatementType.SELECT:
                continue
            what = inner.type.name.replace("_", " ") if inner is not None else "an unrecognised"
            raise _refuse(f"EXPLAIN of {'a ' if inner is not None else ''}{what}")
        if st.type == duckdb.StatementType.PRAGMA:
            try:
                toks = _tokens(st.query)
            except Exception:  # noqa: BLE001
                toks = []
            # PRAGMA name [(args)] only: 'PRAGMA name = value' is a SET
            if (
                _words(toks, 0) == "pragma"
                and _words(toks, 1) in _READ_PRAGMAS
                and not any(t[2] == duckdb.token_type.operator and "=" in t[1] for t in toks)
            ):
                continue
        kind = st.type.name.replace("_", " ")
        if st.type == duckdb.StatementType.LOAD:  # INSTALL and LOAD parse as LOAD
            try:
                first = _words(_tokens(st.query), 0)
            except Exception:  # noqa: BLE001
                first = ""
            kind = first.upper() if first in ("install", "load", "force") else kind
            kind = "INSTALL" if kind == "FORCE" else kind
        raise _refuse(kind)
    return len(statements)


_CONTEXT = re.compile(r"\n\s*LINE \d+:.*", re.DOTALL)


def _first_line(exc: BaseException) -> str:
    """DuckDB's message on one line, without the ``LINE n: <query text>`` context it appends."""
    return " ".join(_CONTEXT.sub("", str(exc)).split())


@dataclass(frozen=True)
class Result:
    """A query result: column names and rows (Python values)."""

    columns: list[str]
    rows: list[tuple[Any, ...]]

    def dicts(self) -> list[dict[str, Any]]:
        """The rows as dicts keyed by column name."""
        return [dict(zip(self.columns, r)) for r in self.rows]

    def column(self, name: str) -> list[Any]:
        """The values of column ``name``, in row order; ValueError for an unknown column."""
        i = self.columns.index(name)
        return [r[i] for r in self.rows]


def run_query(con: duckdb.DuckDBPyConnection, sql: str, params: Mapping[str, Any] | Sequence[Any] | None = None) -> Result:
    """Check that ``sql`` only reads, run it and return the last statement's result."""
    n = check_read_only(con, sql)
    try:
        if n == 1:
            cur = con.execute(sql, params) if params is not None else con.execute(sql)
        else:
            statements = con.extract_statements(sql)
            for st in statements[:-1]:
                con.execute(st.query)
            cur = con.execute(statements[-1].query, params) if params is not None else con.execute(statements[-1].query)
        columns = [d[0] for d in cur.description] if cur.description else []
        rows = cur.fetchall() if cur.description else []
    except duckdb.Error as exc:
        raise QueryError(f"query failed: {_first_line(exc)}") from None
    return Result(columns, rows)


def named_query(con: duckdb.DuckDBPyConnection, name: str, params: Mapping[str, Any] | None = None) -> Result:
    """Run ``reports/sql/<name>.sql``."""
    return run_query(con, load_sql(name), params)
