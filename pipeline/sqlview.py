"""A run's tables as an in-memory, read-only DuckDB connection (the tests query runs with it).

``recap sql`` is the reports package's (``reports.commands.sql_main``). Here every table is read
into memory as Arrow and registered as a view, then DuckDB's file access is switched off and
its configuration locked, so no query can read or write any file (``COPY ... TO``, ``ATTACH``,
``read_csv`` all fail).
"""

from __future__ import annotations

from typing import Any

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
