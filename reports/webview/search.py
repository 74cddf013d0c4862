"""The search column of the viewer: the lower-cased text of every message, read once per part file.

Scanning that column in memory takes about 100 ms per million messages; decoding it from Parquet on
every search would take several times that. Nothing is written anywhere: the run folders stay
untouched.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq


class SearchIndex:
    """Lower-cased message text per messages part file; a part is read once (parts never change
    after their atomic rename, so the path, size and mtime identify its contents)."""

    def __init__(self) -> None:
        self._parts: dict[tuple[str, int, int], pa.Table] = {}

    def table(self, files: Sequence[Path]) -> pa.Table:
        """The search column (run_id, episode_id, seq, lower-cased text) over ``files``: parts already read are
        reused, new ones read, and parts no longer listed forgotten."""
        keep: dict[tuple[str, int, int], pa.Table] = {}
        for f in files:
            try:
                st = f.stat()
            except OSError:
                continue
            key = (str(f), st.st_size, st.st_mtime_ns)
            part = self._parts.get(key)
            if part is None:
                raw = pq.read_table(f, columns=["run_id", "episode_id", "seq", "content"])
                part = pa.table(
                    {
                        "run_id": raw["run_id"],
                        "episode_id": raw["episode_id"],
                        "seq": raw["seq"],
                        "text": pc.utf8_lower(raw["content"]),
                    }
                )
            keep[key] = part
        self._parts = keep
        if not keep:
            return pa.table(
                {
                    "run_id": pa.array([], pa.string()),
                    "episode_id": pa.array([], pa.string()),
                    "seq": pa.array([], pa.int64()),
                    "text": pa.array([], pa.string()),
                }
            )
        return pa.concat_tables(list(keep.values()))
