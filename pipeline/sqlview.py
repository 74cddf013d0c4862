"""``recap sql RUN_DIR "QUERY"``: read-only SQL over a run's tables.

Delegates to the reports package (``reports.commands.sql_main``) when it is installed; this
module is the minimal fallback: every table is read into memory as Arrow and registered as a
view, then DuckDB's file access is switched off and its configuration locked, so no query can
read or write any file (``COPY ... TO``, ``ATTACH``, ``read_csv`` all fail).
"""

from __future__ import annotations

from typing import Any

from rich.markup import escape

from pipeline.errors import PipelineError
from pipeline.store import RunStore


def open_tables(store: RunStore) -> tuple[Any, list[Any]]:
    """An in-memory DuckDB connection with one view per table, and the unreadable parts."""
    import duckdb

    con = duckdb.connect(":memory:")
    bad = []
    for table in store.tables():
        data, b = store.read_table(table)
        bad += b
        con.register(table, data)
    con.execute("SET enable_external_access = false")
    con.execute("SET lock_configuration = true")
    return con, bad


def _delegate() -> Any | None:
    try:
        from reports.commands import sql_main
    except ModuleNotFoundError as exc:
        if exc.name in ("reports.commands", "reports"):
            return None
        raise
    return sql_main


def sql_main(run_dir: str, query: str, console: Any) -> int:
    """``recap sql``: run ``query`` over the run's tables (a fresh mirror for an object-store run); the reports
    package's sql when installed, else this read-only fallback."""
    store = RunStore(run_dir)
    store.require_identity()
    if store.remote:  # query a fresh local copy of an object-store run
        from pipeline.mirror import mirror_dir, pull

        local = mirror_dir(store.location)
        pull(store.location, local)
        run_dir, store = str(local), RunStore(local)
    delegate = _delegate()
    if delegate is not None:
        return int(delegate([run_dir, query]) or 0)
    con, bad = open_tables(store)
    for bp in bad:
        console.print(f"[yellow]skipped unreadable part file {escape(str(bp.path))}: {escape(str(bp.error))}[/yellow]")
    try:
        cur = con.execute(query)
    except Exception as exc:
        raise PipelineError(f"query failed: {str(exc).splitlines()[0]}") from None
    if cur.description is None:
        return 0
    from rich.table import Table
    from rich.text import Text

    t = Table()
    for col in cur.description:
        t.add_column(escape(str(col[0])))
    for row in cur.fetchall():
        # user data: never read as Rich markup
        t.add_row(*(Text("NULL" if v is None else str(v)) for v in row))
    console.print(t)
    return 0
