"""One read-only DuckDB connection over the Parquet tables of one or several run folders.

Why this shape: every number in a report is a SQL query kept in ``reports/sql/``, and the same
views answer ad-hoc questions (``recap sql``). The tables of all given runs are unioned into one
view each (``episodes``, ``llm_calls``, ``messages``, ``tree_nodes``, ``steps``, ``events``,
``run``), and ``reports/sql/views.sql`` adds short named views on top (``attempts``,
``terminal``, ``calls``, ``nodes``, ``tree_stats``, ``failures``, ...).

Read-only is enforced at two levels:

* DuckDB reads the part files natively (fast, with projection and filter pushdown), and once the
  views exist its file access is switched off except for exactly those part files
  (``allowed_paths``), extension loading is off and the configuration is locked. ``COPY ... TO``
  a new file, ``ATTACH``, ``EXPORT``, ``INSTALL``, ``read_csv('/etc/...')`` and ``SET`` all fail.
  The one write DuckDB's settings cannot block is overwriting one of those exact part files with
  ``COPY ... TO '<part file>' (USE_TMP_FILE false)`` through the raw connection;
* every statement that goes through :func:`run_query` (``recap sql``, the report) is parsed first
  and anything that is not a query is refused with a one-line :class:`ReadOnlyError`.

Broken part files (truncated, corrupt footer) are found with :func:`workers.storage.check_parts`,
skipped, logged, and listed in the ``bad_parts`` table. A table without readable files is an
empty view with the table's full schema, and a column missing from every file of an older run
reads as NULL.
"""

from __future__ import annotations

import json
import logging
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import duckdb
import pyarrow as pa

from schemas.tables import TABLES
from workers.storage import check_parts

log = logging.getLogger(__name__)

SQL_DIR = Path(__file__).resolve().with_name("sql")

#: statement types a read-only query may contain (DESCRIBE, SHOW, SUMMARIZE, VALUES and
#: ``FROM x`` all parse as SELECT)
_QUERY_TYPES = {duckdb.StatementType.SELECT, duckdb.StatementType.EXPLAIN}
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
        return f"skipped unreadable part file {self.path} ({self.table}): {self.error}"


# -- opening runs ------------------------------------------------------------------------------


def _resolve_run_dirs(run_dirs: Sequence[str | Path]) -> list[Path]:
    if isinstance(run_dirs, (str, Path)):
        run_dirs = [run_dirs]
    if not run_dirs:
        raise RunDirError("no run folder given")
    out: list[Path] = []
    for raw in run_dirs:
        p = Path(raw).expanduser().resolve()
        if not p.is_dir():
            raise RunDirError(f"run folder {raw} does not exist or is not a folder")
        has_table = any((p / t).is_dir() for t in TABLES)
        if not has_table and not (p / "run.json").is_file():
            raise RunDirError(f"{raw} is not a run folder (no run.json and no table folder such as {p / 'episodes'})")
        if p not in out:
            out.append(p)
    return out


def _run_identity(run_dir: Path) -> str | None:
    """The run id from run.json when it has one (the pipeline writes it once per run)."""
    try:
        data = json.loads((run_dir / "run.json").read_text())
    except (OSError, ValueError):
        return None
    rid = data.get("run_id") if isinstance(data, dict) else None
    return str(rid) if rid is not None else None


def scan_runs(run_dirs: Sequence[str | Path]) -> tuple[list[Path], dict[str, list[Path]], list[SkippedPart]]:
    """Readable part files per table over all runs, and the broken ones."""
    dirs = _resolve_run_dirs(run_dirs)
    files: dict[str, list[Path]] = {t: [] for t in TABLES}
    skipped: list[SkippedPart] = []
    for d in dirs:
        for table in TABLES:
            good, bad = check_parts(d, table)
            files[table].extend(good)
            skipped.extend(SkippedPart(str(d), table, str(b.path), b.error) for b in bad)
    return dirs, files, skipped


@lru_cache(maxsize=None)
def duckdb_types() -> dict[str, dict[str, str]]:
    """DuckDB's type for every column of every table, from the Arrow schemas."""
    con = duckdb.connect(":memory:")
    out: dict[str, dict[str, str]] = {}
    for table, schema in TABLES.items():
        empty = schema.empty_table()  # noqa: F841 - read by DuckDB's replacement scan below
        out[table] = {name: typ for name, typ in con.execute("SELECT column_name, column_type FROM (DESCRIBE SELECT * FROM empty)").fetchall()}
    con.close()
    return out


def _sql_str(text: str) -> str:
    return "'" + text.replace("'", "''") + "'"


def _create_table_view(con: duckdb.DuckDBPyConnection, table: str, files: list[Path]) -> None:
    """View ``table`` over ``files`` with exactly the declared columns and types."""
    types = duckdb_types()[table]
    if not files:
        cols = ", ".join(f'CAST(NULL AS {t}) AS "{c}"' for c, t in types.items())
        con.execute(f'CREATE VIEW "{table}" AS SELECT {cols} WHERE false')
        return
    source = f"read_parquet([{', '.join(_sql_str(str(f)) for f in files)}], union_by_name = true)"
    present = {r[0] for r in con.execute(f"SELECT column_name FROM (DESCRIBE SELECT * FROM {source})").fetchall()}
    cols = ", ".join(
        f'CAST("{c}" AS {t}) AS "{c}"' if c in present else f'CAST(NULL AS {t}) AS "{c}"' for c, t in types.items()
    )
    con.execute(f'CREATE VIEW "{table}" AS SELECT {cols} FROM {source}')


def open_runs(run_dirs: Sequence[str | Path], *, read_only: bool = True) -> duckdb.DuckDBPyConnection:
    """An in-memory DuckDB with a view per table over the readable parts of all ``run_dirs``.

    Unreadable part files are skipped (logged as warnings, listed in ``bad_parts``).
    ``read_only=False`` leaves DuckDB's file access on (for callers that export on purpose).
    """
    con, _ = open_runs_checked(run_dirs, read_only=read_only)
    return con


def open_runs_checked(
    run_dirs: Sequence[str | Path], *, read_only: bool = True
) -> tuple[duckdb.DuckDBPyConnection, list[SkippedPart]]:
    """:func:`open_runs` that also returns the skipped part files."""
    dirs, files, skipped = scan_runs(run_dirs)
    for s in skipped:
        log.warning(s.line())
    con = duckdb.connect(":memory:")
    con.execute("SET parquet_metadata_cache = true")
    for table, parts in files.items():
        _create_table_view(con, table, parts)
    con.execute("CREATE TABLE bad_parts (run_dir VARCHAR, \"table\" VARCHAR, path VARCHAR, error VARCHAR)")
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
        allowed = [str(f) for fs in files.values() for f in fs]
        con.execute("SET allowed_paths = ?", [allowed])
        con.execute("SET allowed_directories = []")
        con.execute("SET enable_external_access = false")
        con.execute("SET autoinstall_known_extensions = false")
        con.execute("SET autoload_known_extensions = false")
        con.execute("SET lock_configuration = true")
    return con, skipped


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


@lru_cache(maxsize=None)
def load_sql(name: str) -> str:
    """The text of ``reports/sql/<name>.sql``."""
    path = SQL_DIR / f"{name}.sql"
    if not path.is_file():
        known = ", ".join(sorted(p.stem for p in SQL_DIR.glob("*.sql")))
        raise ReportError(f"no report query named {name!r}; known: {known}")
    return path.read_text()


def sql_names() -> list[str]:
    return sorted(p.stem for p in SQL_DIR.glob("*.sql"))


_COMMENT = re.compile(r"--[^\n]*")


def split_statements(text: str) -> list[str]:
    """Split a SQL file on ``;`` at line ends (our files never put ``;`` inside strings)."""
    body = _COMMENT.sub("", text)
    return [s.strip() for s in re.split(r";\s*(?:\n|$)", body) if s.strip()]


# -- read-only queries ---------------------------------------------------------------------------


def check_read_only(con: duckdb.DuckDBPyConnection, sql: str) -> int:
    """Raise :class:`ReadOnlyError` unless every statement in ``sql`` only reads.

    Returns the number of statements. Allowed: SELECT/WITH/VALUES/FROM, DESCRIBE, SHOW,
    SUMMARIZE, EXPLAIN and the read-only PRAGMAs.
    """
    try:
        statements = con.extract_statements(sql)
    except duckdb.Error as exc:
        raise QueryError(f"cannot parse query: {_first_line(exc)}") from None
    if not statements:
        raise QueryError("empty query")
    for st in statements:
        if st.type in _QUERY_TYPES:
            continue
        if st.type == duckdb.StatementType.PRAGMA:
            m = re.match(r"\s*pragma\s+([a-z_]+)", st.query, re.IGNORECASE)
            if m and m.group(1).lower() in _READ_PRAGMAS:
                continue
        kind = st.type.name.replace("_", " ")
        if st.type == duckdb.StatementType.LOAD:  # INSTALL and LOAD parse as LOAD
            kind = st.query.split(None, 1)[0].upper() if st.query.strip() else kind
        raise ReadOnlyError(
            f"refused {kind} statement: reports are read-only "
            f"(allowed: SELECT, WITH, DESCRIBE, SHOW, SUMMARIZE, EXPLAIN, read-only PRAGMA)"
        )
    return len(statements)


def _first_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


@dataclass(frozen=True)
class Result:
    """A query result: column names and rows (Python values)."""

    columns: list[str]
    rows: list[tuple[Any, ...]]

    def dicts(self) -> list[dict[str, Any]]:
        return [dict(zip(self.columns, r)) for r in self.rows]

    def column(self, name: str) -> list[Any]:
        i = self.columns.index(name)
        return [r[i] for r in self.rows]


def run_query(
    con: duckdb.DuckDBPyConnection, sql: str, params: Mapping[str, Any] | Sequence[Any] | None = None
) -> Result:
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


def arrow_query(con: duckdb.DuckDBPyConnection, sql: str, params: Mapping[str, Any] | None = None) -> pa.Table:
    check_read_only(con, sql)
    try:
        return (con.execute(sql, params) if params is not None else con.execute(sql)).fetch_arrow_table()
    except duckdb.Error as exc:
        raise QueryError(f"query failed: {_first_line(exc)}") from None
