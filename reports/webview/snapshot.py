"""One snapshot of the run folders: a locked-down DuckDB connection with the episode list and search column.

A :class:`Snapshot` is one read-only DuckDB connection from :func:`reports.views.open_runs_checked`
(the part files reach DuckDB as Arrow datasets; DuckDB's file access is off and its configuration
locked), with the report's views (``attempts``, ``episode_modes``, ``calls``, ...) and two things
held in memory so that every list and filter stays far under 300 ms on a million messages:

* ``_episode_list``: one row per episode row (every attempt), the labels of ``attempts`` and the
  ``mode`` of ``episode_modes`` (about 10,000 rows);
* ``_search``: the lower-cased text of every message with its (run, episode, seq), kept per part
  file in :class:`reports.webview.search.SearchIndex` so that a new part costs only its own rows.

Queries on one snapshot are serialised (one DuckDB connection is not shared between threads).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import duckdb

from reports.sections import load_plans
from reports.views import Result, SkippedPart, materialize, named_query, open_runs_checked, run_query, scan_runs
from reports.webview.search import SearchIndex

#: filters of the episode list: (parameter, column of _episode_list); optional ones only when present
FILTERS: tuple[tuple[str, str], ...] = (
    ("run", "run_id"),
    ("model", "model_label"),
    ("label", "label"),
    ("arm", "arm"),
    ("method", "method"),
    ("profile", "profile"),
    ("ablation", "ablation"),
    ("benchmark", "benchmark"),
    ("split", "split"),
    ("task", "task"),
    ("end_reason", "end_reason"),
    ("mode", "mode"),
    ("success", "success"),
)
#: searches whose hits a snapshot keeps (paging or re-sorting a search does not scan again)
SEARCH_CACHE = 16


_LIST_SQL = """
CREATE TEMP TABLE _episode_list AS
SELECT a.*, m.mode
FROM attempts a
LEFT JOIN episode_modes m ON m.run_id = a.run_id AND m.episode_id = a.episode_id
"""


@dataclass
class Snapshot:
    """A locked-down connection over the run folders as they were at ``built_at``."""

    con: duckdb.DuckDBPyConnection
    run_dirs: list[Path]
    columns: set[str]
    options: dict[str, list[Any]]
    skipped: list[SkippedPart]
    built_at: float
    lock: threading.Lock = field(default_factory=threading.Lock)
    #: search text -> temp table of its hits (run_id, episode_id, hits, first_hit), newest last
    hits: dict[str, str] = field(default_factory=dict)

    def hits_table(self, text: str) -> str:
        """The temp table of the episodes whose messages hold ``text`` (lower case): one scan of
        the search column per distinct text, kept for the next pages, sorts and filters."""
        with self.lock:
            name = self.hits.pop(text, None)
            if name is None:
                name = f"_hits_{len(self.hits)}_{int(time.time() * 1e6)}"
                self.con.execute(
                    f"CREATE TEMP TABLE {name} AS SELECT run_id, episode_id, count(*) AS hits, min(seq) AS first_hit "
                    "FROM _search WHERE contains(text, $q) GROUP BY ALL",
                    {"q": text},
                )
                while len(self.hits) >= SEARCH_CACHE:
                    old = self.hits.pop(next(iter(self.hits)))
                    self.con.execute(f"DROP TABLE IF EXISTS {old}")
            self.hits[text] = name
            return name

    def query(self, sql: str, params: dict[str, Any] | None = None) -> Result:
        """Run a read-only query on this snapshot (serialised: the connection is not shared between threads)."""
        with self.lock:
            return run_query(self.con, sql, params)

    def named(self, name: str, params: dict[str, Any] | None = None) -> Result:
        """Run a stored query (``reports/sql/<name>.sql``) on this snapshot, serialised like :meth:`query`."""
        with self.lock:
            return named_query(self.con, name, params)

    def close(self) -> None:
        """Close the connection once no query holds the lock (the snapshot was replaced)."""
        with self.lock:
            self.con.close()


def build_snapshot(run_dirs: Sequence[Path], index: SearchIndex) -> Snapshot:
    """A fresh snapshot of ``run_dirs``: the views, the in-memory episode list and search column, and the values
    each filter can take. Reads only."""
    dirs, files, _ = scan_runs(run_dirs)
    con, skipped = open_runs_checked(dirs)
    try:
        materialize(con, ("attempts", "episode_modes"))
        con.execute(_LIST_SQL)
        search = index.table(files["messages"])  # noqa: F841 - registered below
        con.register("_search", search)
        load_plans(con)
        columns = {r[0] for r in con.execute("SELECT column_name FROM (DESCRIBE SELECT * FROM _episode_list)").fetchall()}
        options: dict[str, list[Any]] = {}
        for param, col in FILTERS:
            if col in columns:
                options[param] = [
                    r[0]
                    for r in con.execute(
                        f'SELECT DISTINCT "{col}" FROM _episode_list WHERE "{col}" IS NOT NULL ORDER BY 1'
                    ).fetchall()
                ]
    except BaseException:
        con.close()
        raise
    return Snapshot(con, dirs, columns, options, skipped, time.time())
