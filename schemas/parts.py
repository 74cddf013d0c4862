"""Run-folder part files: atomic Parquet parts, one folder per table, and the one schema rule
every reader (pipeline, workers, reports) applies to them.

Layout of a run folder::

    RUN_DIR/
      run.json                    # identity of the run (run_id, spec hash) - written once
      <table>/part-<writer>-<n>.parquet

Every writer (the sink actor, each gateway) writes its own part files under a temporary name and
renames them into place, so a reader never sees a half-written file and a crash loses at most the
batch in flight. Readers skip (and report) part files that cannot be read.
"""

from __future__ import annotations

import json
import os
import sys
import threading
import uuid
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from schemas.tables import TABLES, arrow_schema, record_to_row
from schemas.versions import missing_fillable, part_version, stored_names, upgrade

if TYPE_CHECKING:
    import pyarrow as pa

# pyarrow (and numpy with it) is imported by the functions that read or write a part, not with
# this module: a process that only names part files or holds a handle to the sink (an episode
# worker: Ray loads the sink's class to deserialise its handle) never loads it (issue 37, item 3).

#: the run folder's identity file: written once by the pipeline when the run starts
RUN_FILE = "run.json"


def read_run_file(run_dir: Path | str) -> dict[str, Any] | None:
    """The fields of ``RUN_DIR/run.json``, or None when it is missing, unreadable or not an
    object. The one reader of a local run folder's identity (the pipeline's RunStore also reads
    it from object stores, through the same file name)."""
    try:
        data = json.loads((Path(run_dir) / RUN_FILE).read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


_no_pandas_lock = threading.Lock()


def arrow_without_pandas() -> None:
    """Have pyarrow build arrays from Python rows without importing pandas, in a process that
    has not imported pandas itself.

    Why: pyarrow's ``pa.array`` (under ``Table.from_pylist``) asks its pandas shim whether a
    value is a pandas object, and the shim's first question imports pandas (~40 MB, ~300
    modules) - into the sink and every gateway, which only write Python rows (issue 37, item 3).
    The shim asks once per process and remembers the answer; with ``pandas`` blocked for that
    one question it answers "no pandas" (pyarrow's own path when pandas is not installed), so
    rows are converted exactly as before. Nothing here passes pandas objects to pyarrow; an
    explicit ``to_pandas``/``from_pandas`` later still imports pandas (the shim retries then).
    A process that already holds pandas is left as it is."""
    if "pandas" in sys.modules:
        return
    import pyarrow as pa

    with _no_pandas_lock:
        if "pandas" in sys.modules:
            return
        sys.modules["pandas"] = None  # type: ignore[assignment]  # import pandas -> ImportError
        try:
            pa.lib._pandas_api.have_pandas  # noqa: B018  # the shim's one import attempt, answered "none"
        except Exception:  # another pyarrow layout: pandas may load on the first write, as before
            pass
        finally:
            del sys.modules["pandas"]


@dataclass
class PartWriter:
    """Writes batches of rows of any table as atomic part files under ``run_dir``."""

    run_dir: Path
    writer: str = field(default_factory=lambda: uuid.uuid4().hex[:8])
    _n: int = 0

    def __post_init__(self) -> None:
        self.run_dir = Path(self.run_dir)
        arrow_without_pandas()

    def write_rows(self, table: str, rows: Sequence[dict[str, Any]]) -> Path | None:
        """Write ``rows`` as one new part file of ``table`` (temp name, fsync, rename); returns its path, or None
        when there are no rows (no empty parts)."""
        if not rows:
            return None
        import pyarrow as pa
        import pyarrow.parquet as pq

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
    """A part file a reader skipped, and why (one line)."""

    path: Path
    error: str


def is_part_name(name: str) -> bool:
    """Whether a file name is a part file's (``part-*.parquet``); writers' temp files are not."""
    return name.startswith("part-") and name.endswith(".parquet")


def part_files(run_dir: Path, table: str) -> list[Path]:
    """The part files of ``table`` in a local run folder (:func:`is_part_name`, sorted);
    [] when the table has no folder."""
    folder = Path(run_dir) / table
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.iterdir() if p.is_file() and is_part_name(p.name))


def schema_problem(table: str, found: pa.Schema) -> str | None:
    """Why a part file whose schema is ``found`` is not a ``table`` part, or None when it is.

    The one rule every reader applies (``recap status``, ``recap sql``, ``recap report``, resume
    through :func:`read_parts`): a part holds every column of the table's Arrow schema
    (``schemas/``) with exactly the declared type - except a part of an earlier schema version,
    which may lack the columns added since (:func:`schemas.versions.missing_fillable`; its rows
    are mapped on read, :func:`schemas.versions.upgrade`). Extra columns are ignored. A part that breaks
    the rule is skipped and named, never cast, so a number stored as text is not counted by one
    reader and refused by another.
    """
    import pyarrow as pa

    expected = arrow_schema(table)
    version = part_version(found)
    stored = stored_names(table, found.names, version)  # a column renamed since: its old name
    missing = [f.name for f in expected if f.name not in stored]
    if missing and missing_fillable(table, missing, version):
        expected = pa.schema([f for f in expected if f.name not in missing])  # mapped on read
        missing = []
    if missing:
        more = f" (+{len(missing) - 5} more)" if len(missing) > 5 else ""
        return f"not a {table} part: missing column(s) {', '.join(sorted(missing)[:5])}{more}"
    wrong: list[str] = []
    for f in expected:
        i = found.get_field_index(stored[f.name])
        if i < 0:
            wrong.append(f"{f.name} appears more than once")
        elif not found.field(i).type.equals(f.type):
            wrong.append(f"{f.name} is {found.field(i).type}, expected {f.type}")
    if wrong:
        more = f" (+{len(wrong) - 3} more)" if len(wrong) > 3 else ""
        return f"not a {table} part: wrong column type(s): {'; '.join(wrong[:3])}{more}"
    return None


def _error(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}".splitlines()[0][:300]


def _source(path: Any, open_file: Callable[[str], Any] | None) -> Any:
    return open_file(str(path)) if open_file is not None else path


def inspect_parts(
    paths: Iterable[Any], table: str, open_file: Callable[[str], Any] | None = None
) -> tuple[list[Any], list[BadPart]]:
    """Split part files into good ones and bad ones from their footers alone: unreadable
    (truncated, corrupt, empty) or not matching the table's schema (:func:`schema_problem`).

    ``open_file`` opens a path of a remote file system (``fs.open_input_file``); local paths
    are read directly.
    """
    import pyarrow.parquet as pq

    good: list[Any] = []
    bad: list[BadPart] = []
    for p in paths:
        try:
            src = _source(p, open_file)
            try:
                found = pq.read_schema(src)
            finally:
                if src is not p and hasattr(src, "close"):
                    src.close()
            problem = schema_problem(table, found)
            if problem is not None:
                raise ValueError(problem)
            good.append(p)
        except Exception as exc:  # pyarrow raises several types for broken files
            bad.append(BadPart(Path(str(p)), _error(exc)))
    return good, bad


def read_parts(
    paths: Iterable[Any],
    table: str,
    columns: Sequence[str] | None = None,
    open_file: Callable[[str], Any] | None = None,
) -> tuple[pa.Table, list[BadPart]]:
    """The rows of the good part files among ``paths`` (optionally a few columns) and the bad
    ones (see :func:`inspect_parts`); an empty table with the schema when none is good."""
    import pyarrow as pa

    full = arrow_schema(table)
    schema = pa.schema([full.field(c) for c in columns]) if columns is not None else full
    good, bad = inspect_parts(paths, table, open_file)
    pieces = []
    for p in good:
        try:
            src = _source(p, open_file)
            try:
                pieces.append(read_part(src, table).select(schema.names).cast(schema))
            finally:
                if src is not p and hasattr(src, "close"):
                    src.close()
        except Exception as exc:  # a footer that reads but data pages that do not
            bad.append(BadPart(Path(str(p)), _error(exc)))
    if not pieces:
        return schema.empty_table(), bad
    return pa.concat_tables(pieces), bad


def read_part(source: Any, table: str) -> pa.Table:
    """Every row of one good part file, in the table's current schema: a part of an earlier
    schema version is mapped (:func:`schemas.versions.upgrade`)."""
    import pyarrow.parquet as pq

    full = arrow_schema(table)
    found = pq.read_schema(source)
    if all(name in found.names for name in full.names):
        return pq.read_table(source, columns=list(full.names)).select(full.names).cast(full)
    version = part_version(found)
    stored = stored_names(table, found.names, version)
    missing = [f.name for f in full if f.name not in stored]
    if version is None or (missing and not missing_fillable(table, missing, version)):
        raise ValueError(f"not a {table} part: missing column(s) {', '.join(sorted(missing)[:5])}")
    return upgrade(table, pq.read_table(source, columns=list(stored.values())), version)


def check_parts(run_dir: Path, table: str) -> tuple[list[Path], list[BadPart]]:
    """Split a table's part files into good ones and bad ones (truncated, corrupt, or not
    matching the table's schema: :func:`schema_problem`)."""
    return inspect_parts(part_files(run_dir, table), table)


def read_table(run_dir: Path, table: str) -> tuple[pa.Table, list[BadPart]]:
    """All rows of the good part files of ``table`` (empty table with the schema when none),
    plus the bad parts."""
    return read_parts(part_files(run_dir, table), table)


def known_tables() -> list[str]:
    """The names of the run tables (schemas.tables), in their declared order."""
    return list(TABLES)
