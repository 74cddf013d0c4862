"""The sink: one actor that batches every worker's rows and writes Parquet part files.

Why one sink: hundreds of episodes each emitting a few hundred small records would otherwise
produce thousands of tiny files. The sink buffers rows per table and writes a part file per
table when a buffer is large or old enough, through :class:`workers.storage.PartWriter` (temp
name, fsync, rename), always into a local folder (a run on an object store writes a local
mirror that the driver uploads; see :mod:`pipeline.mirror`). The terminal ``episodes`` rows are written after every other table of the same
flush, so an episode row never precedes the rows it summarises on disk.

The core (:class:`Sink`) is plain Python; :func:`sink_actor` wraps it as a Ray actor.
"""

from __future__ import annotations

import time
import uuid
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from schemas.tables import record_to_row
from workers.storage import PartWriter

#: written last in every flush
_LAST = ("episodes",)


def is_uri(location: str) -> bool:
    """An object-store (or any pyarrow filesystem) URI rather than a local path."""
    return "://" in str(location)


class Sink:
    """Buffers rows by table and writes them as part files (see the module docstring)."""

    def __init__(self, location: str, run_id: str, *, writer: str | None = None,
                 flush_rows: int = 5000, flush_s: float = 2.0) -> None:
        self.run_id = run_id
        self.writer = PartWriter(Path(location), writer or f"sink{uuid.uuid4().hex[:6]}")
        self.flush_rows = flush_rows
        self.flush_s = flush_s
        self._buffer: dict[str, list[dict[str, Any]]] = {}
        self._buffered = 0
        self._last_flush = time.monotonic()
        self.rows_written = 0
        self.files_written = 0
        self.write_seconds = 0.0
        self.rows_by_table: dict[str, int] = {}

    # -- input ----------------------------------------------------------------------------------
    def add(self, rows_by_table: Mapping[str, Sequence[dict[str, Any]]]) -> int:
        """Add rows (already stamped with the run id); flushes when due. Returns rows buffered."""
        for table, rows in rows_by_table.items():
            if rows:
                self._buffer.setdefault(table, []).extend(rows)
                self._buffered += len(rows)
        self.maybe_flush()
        return self._buffered

    def add_records(self, records: Iterable[Any], flush: bool = False) -> int:
        by_table: dict[str, list[dict[str, Any]]] = {}
        for rec in records:
            by_table.setdefault(type(rec).table, []).append(record_to_row(rec, self.run_id))
        self.add(by_table)
        if flush:
            self.flush()
        return self._buffered

    # -- output ---------------------------------------------------------------------------------
    def maybe_flush(self) -> int:
        if self._buffered >= self.flush_rows or (self._buffered and time.monotonic() - self._last_flush >= self.flush_s):
            return self.flush()
        return 0

    def flush(self) -> int:
        """Write every buffered row now; returns the number of rows written."""
        buffer, self._buffer, n = self._buffer, {}, self._buffered
        self._buffered = 0
        self._last_flush = time.monotonic()
        if not n:
            return 0
        t0 = time.perf_counter()
        order = sorted(buffer, key=lambda t: (t in _LAST, t))
        for table in order:
            rows = buffer[table]
            if self.writer.write_rows(table, rows) is not None:
                self.files_written += 1
                self.rows_written += len(rows)
                self.rows_by_table[table] = self.rows_by_table.get(table, 0) + len(rows)
        self.write_seconds += time.perf_counter() - t0
        return n

    def stats(self) -> dict[str, Any]:
        return {
            "rows_written": self.rows_written,
            "files_written": self.files_written,
            "rows_buffered": self._buffered,
            "write_seconds": self.write_seconds,
            "rows_by_table": dict(self.rows_by_table),
        }


def sink_actor(runtime_env: dict | None = None) -> Any:
    """The Sink as a Ray actor (no CPU reservation: it mostly waits on the disk)."""
    import ray

    options: dict[str, Any] = {"num_cpus": 0, "max_restarts": 0}
    if runtime_env:
        options["runtime_env"] = runtime_env
    return ray.remote(**options)(Sink)
