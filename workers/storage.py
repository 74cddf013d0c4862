"""Run-folder storage: atomic Parquet part files, one folder per table.

Layout of a run folder::

    RUN_DIR/
      run.json                    # identity of the run (run_id, spec hash) - written once
      <table>/part-<writer>-<n>.parquet

Every writer (the sink actor, each gateway) writes its own part files under a temporary name and
renames them into place, so a reader never sees a half-written file and a crash loses at most the
batch in flight. Readers skip (and report) part files that cannot be read.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from schemas.tables import TABLES, arrow_schema, record_to_row


@dataclass
class PartWriter:
    """Writes batches of rows of any table as atomic part files under ``run_dir``."""

    run_dir: Path
    writer: str = field(default_factory=lambda: uuid.uuid4().hex[:8])
    _n: int = 0

    def __post_init__(self) -> None:
        self.run_dir = Path(self.run_dir)

    def write_rows(self, table: str, rows: Sequence[dict[str, Any]]) -> Path | None:
        if not rows:
            return None
        data = pa.Table.from_pylist(list(rows), schema=arrow_schema(table))
        folder = self.run_dir / table
        folder.mkdir(parents=True, exist_ok=True)
        self._n += 1
        final = folder / f"part-{self.writer}-{self._n:06d}.parquet"
        tmp = folder / f".tmp-{final.name}"
        pq.write_table(data, tmp)
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, final)
        return final

    def write_records(self, run_id: str, records: Iterable[Any]) -> list[Path]:
        """Group records by table and write one part file per table."""
        by_table: dict[str, list[dict[str, Any]]] = {}
        for rec in records:
            by_table.setdefault(type(rec).table, []).append(record_to_row(rec, run_id))
        return [p for t, rows in by_table.items() if (p := self.write_rows(t, rows)) is not None]


@dataclass(frozen=True)
class BadPart:
    path: Path
    error: str


def part_files(run_dir: Path, table: str) -> list[Path]:
    folder = Path(run_dir) / table
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.glob("part-*.parquet"))


def check_parts(run_dir: Path, table: str) -> tuple[list[Path], list[BadPart]]:
    """Split a table's part files into readable ones and broken ones (truncated, corrupt)."""
    good: list[Path] = []
    bad: list[BadPart] = []
    for p in part_files(run_dir, table):
        try:
            pq.read_metadata(p)
            good.append(p)
        except Exception as exc:  # pyarrow raises several types for broken files
            bad.append(BadPart(p, f"{type(exc).__name__}: {exc}"))
    return good, bad


def read_table(run_dir: Path, table: str) -> tuple[pa.Table, list[BadPart]]:
    """All readable rows of ``table`` (empty table with the schema when none), plus bad parts."""
    good, bad = check_parts(run_dir, table)
    pieces = []
    for p in good:
        try:
            pieces.append(pq.read_table(p, schema=arrow_schema(table)))
        except Exception as exc:
            bad.append(BadPart(p, f"{type(exc).__name__}: {exc}"))
    if not pieces:
        return arrow_schema(table).empty_table(), bad
    return pa.concat_tables(pieces), bad


def known_tables() -> list[str]:
    return list(TABLES)
