"""A run's tables as an in-memory, read-only DuckDB connection (the tests query runs with it).

``recap sql`` is :mod:`pipeline.cli.sql`. Here every table is read
into memory as Arrow and registered as a view, then DuckDB's file access is switched off and
its configuration locked, so no query can read or write any file (``COPY ... TO``, ``ATTACH``,
``read_csv`` all fail).
"""

from __future__ import annotations

import duckdb

from pipeline.store import RunStore
from schemas.parts import BadPart


def open_tables(store: RunStore) -> tuple[duckdb.DuckDBPyConnection, list[BadPart]]:
    """An in-memory DuckDB connection with one view per table, and the unreadable parts."""
    con = duckdb.connect(":memory:")
    bad: list[BadPart] = []
    for table in store.tables():
        data, b = store.read_table(table)
        bad += b
        con.register(table, data)
    con.execute("SET enable_external_access = false")
    con.execute("SET lock_configuration = true")
    return con, bad
