"""The sink: one actor that batches every worker's rows and writes Parquet part files.

Why one sink: hundreds of episodes each emitting a few hundred small records would otherwise
produce thousands of tiny files. The sink buffers rows per table and writes a part file per
table when a buffer is large or old enough, through :class:`schemas.parts.PartWriter` (temp
name, fsync, rename), always into a local folder (a run on an object store writes a local
mirror that the driver uploads; see :mod:`pipeline.mirror`). The terminal ``episodes`` rows are written after every other table of the same
flush, so an episode row never precedes the rows it summarises on disk.

Durability (why a ``kill -9`` of the sink loses nothing it acknowledged): every batch is
appended to a write-ahead log segment (``RUN_DIR/.sink-wal/.tmp-<writer>-<n>.wal``, written
and flushed - all a process kill needs) *before* the call that brought it returns. A flush
writes the buffered rows as the parts of segment ``n`` (``part-<writer>-<n>.parquet``, one per
table, named by the segment, so writing a segment twice replaces a part by the same rows) and
only then retires the segment. The Ray actor is restartable (``max_restarts``) and its calls
are retried on the new incarnation (``max_task_retries``): the new one replays its own
segments into their parts, and a batch that was logged but whose reply the kill swallowed is
recognised by its content hash when its sender retries it, so it is not written twice. A
segment left by a driver that died with its sink is replayed by the next driver
(:func:`recover_wal`) before it reads what the run folder holds. The segment files' ``.tmp-``
prefix keeps them out of object-store uploads; a finished session removes them
(:meth:`Sink.close`).

The core (:class:`Sink`) is plain Python; :func:`sink_actor` wraps it as a Ray actor.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import pickle
import re
import struct
import time
import uuid
import zlib
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from schemas.parts import PartWriter
from schemas.tables import record_to_row
from workers.log_setup import configure_from_env

log = logging.getLogger(__name__)

#: written last in every flush
_LAST = ("episodes",)
#: the write-ahead log folder, relative to the run folder
WAL_DIR = ".sink-wal"
#: how many retired segments a sink keeps at least (their batch hashes answer retried sends) ...
_KEEP_DONE = 2
#: ... and for how long it keeps every segment it retired: Ray re-sends the calls a kill swallowed
#: in no set order with other senders' new calls ("the task execution order is not guaranteed when
#: task retries occur", Ray's docs on actor task order), so a restarted sink may retire several
#: segments before an old batch comes again; by time, so a soak's memory stays bounded
_KEEP_DONE_S = 300.0
#: restarts of a killed sink actor before the driver gives up on it
SINK_MAX_RESTARTS = 20
_HEADER = struct.Struct("<II")  # payload length, crc32
_SEGMENT = re.compile(r"^\.tmp-(?P<writer>.+)-(?P<seg>\d{6,})\.(?P<state>wal|done)$")


def is_uri(location: str) -> bool:
    """An object-store (or any pyarrow filesystem) URI rather than a local path."""
    return "://" in str(location)


# --------------------------------------------------------------------------------------------
# the write-ahead log
# --------------------------------------------------------------------------------------------
def batch_hash(rows_by_table: Mapping[str, Sequence[dict[str, Any]]]) -> str:
    """A content hash of a batch (rows carry episode ids, sequence numbers and timestamps, so
    two different batches never share one)."""
    canon = json.dumps({t: list(r) for t, r in rows_by_table.items() if r}, sort_keys=True, default=str, separators=(",", ":"))
    return hashlib.blake2b(canon.encode(), digest_size=16).hexdigest()


def _segment_path(run_dir: Path, writer: str, seg: int, state: str = "wal") -> Path:
    return Path(run_dir) / WAL_DIR / f".tmp-{writer}-{seg:06d}.{state}"


def _segments(run_dir: Path, writer: str | None = None) -> list[tuple[str, int, str, Path]]:
    """(writer, segment, state, path) of the log files under ``run_dir``, oldest first."""
    folder = Path(run_dir) / WAL_DIR
    if not folder.is_dir():
        return []
    out = []
    for p in folder.iterdir():
        m = _SEGMENT.match(p.name)
        if m and (writer is None or m["writer"] == writer):
            out.append((m["writer"], int(m["seg"]), m["state"], p))
    return sorted(out, key=lambda s: (s[0], s[1], s[2]))


def read_segment(path: Path) -> Iterator[tuple[str, dict[str, list[dict[str, Any]]]]]:
    """(hash, rows by table) of every complete entry; a torn last entry (a kill mid-append,
    never acknowledged) ends the segment."""
    try:
        data = Path(path).read_bytes()
    except FileNotFoundError:
        return
    pos = 0
    while pos + _HEADER.size <= len(data):
        size, crc = _HEADER.unpack_from(data, pos)
        payload = data[pos + _HEADER.size : pos + _HEADER.size + size]
        if len(payload) < size or zlib.crc32(payload) != crc:
            return
        try:
            entry = pickle.loads(payload)
        except Exception:
            return
        yield entry["h"], entry["rows"]
        pos += _HEADER.size + size


def _write_segment_parts(writer: PartWriter | Any, seg: int, buffer: Mapping[str, Sequence[dict[str, Any]]]) -> dict[str, int]:
    """The rows of one segment as its part files, ``episodes`` last; rows written per table."""
    written: dict[str, int] = {}
    for table in sorted(buffer, key=lambda t: (t in _LAST, t)):
        rows = buffer[table]
        if not rows:
            continue
        # part-<writer>-<seg>: PartWriter numbers its next part _n + 1
        writer._n = seg - 1
        path = writer.write_rows(table, rows)
        if path is not None:
            if (
                isinstance(path, Path) and path.name != f"part-{getattr(writer, 'writer', '')}-{seg:06d}.parquet"
            ):  # the naming the log relies on changed
                raise RuntimeError(f"sink part {path.name} is not named after its log segment {seg}")
            written[table] = len(rows)
    return written


@dataclass
class Recovered:
    """What :func:`recover_wal` found: rows written now, and the hash of every batch the log
    held (written now or by its sink before), so a sender can tell which of its batches the
    dead sink had taken."""

    rows: int = 0
    hashes: set[str] = field(default_factory=set)


def recover_wal(run_dir: Path | str, writer: str | None = None) -> Recovered:
    """Write the rows of every log segment left under ``run_dir`` (by sinks that died with
    their driver) as their parts, then remove the segments.

    Safe to run twice and beside a sink finishing the same segment: a segment's parts are
    named by the segment and hold the same rows whoever writes them."""
    out = Recovered()
    for w, seg, state, path in _segments(Path(run_dir), writer):
        buffer: dict[str, list[dict[str, Any]]] = {}
        for h, rows_by_table in read_segment(path):
            if h in out.hashes:
                continue
            out.hashes.add(h)
            for table, rows in rows_by_table.items():
                buffer.setdefault(table, []).extend(rows)
        if state == "wal":
            out.rows += sum(_write_segment_parts(PartWriter(Path(run_dir), w), seg, buffer).values())
        path.unlink(missing_ok=True)
    try:
        (Path(run_dir) / WAL_DIR).rmdir()
    except OSError:
        pass
    return out


def records_by_table(records: Iterable[Any], run_id: str) -> dict[str, list[dict[str, Any]]]:
    """Records as rows stamped with the run id, grouped by table (what :meth:`Sink.add` takes)."""
    by_table: dict[str, list[dict[str, Any]]] = {}
    for rec in records:
        by_table.setdefault(type(rec).table, []).append(record_to_row(rec, run_id))
    return by_table


# --------------------------------------------------------------------------------------------
class Sink:
    """Buffers rows by table and writes them as part files (see the module docstring)."""

    def __init__(
        self,
        location: str,
        run_id: str,
        *,
        writer: str | None = None,
        flush_rows: int = 5000,
        flush_s: float = 2.0,
        wal: bool = True,
    ) -> None:
        self.run_id = run_id
        self.run_dir = Path(location)
        self.writer = PartWriter(self.run_dir, writer or f"sink{uuid.uuid4().hex[:8]}")
        self.name = self.writer.writer
        self.flush_rows = flush_rows
        self.flush_s = flush_s
        self.wal = wal
        self._buffer: dict[str, list[dict[str, Any]]] = {}
        self._buffered = 0
        self._last_flush = time.monotonic()
        self.rows_written = 0
        self.files_written = 0
        self.write_seconds = 0.0
        self.rows_by_table: dict[str, int] = {}
        #: hashes of the batches of the open segment and of the last retired ones, by segment ...
        self._hashes: dict[int, set[str]] = {}
        #: ... and every one of them, for an O(1) check per batch
        self._known_hashes: set[str] = set()
        #: when each segment this process retired was retired (monotonic seconds, oldest first): the
        #: only segments :meth:`_prune` forgets; those a previous process of this writer logged are
        #: known for this process's whole life (the calls whose replies its kill swallowed come back
        #: whenever Ray re-sends them)
        self._retired_at: dict[int, float] = {}
        self._wal_fh: Any = None
        self.recovered_rows = 0
        self.seg = 1
        if wal:
            self._recover()
            if self.recovered_rows:
                log.warning("sink %s restarted: wrote %d rows its previous process had logged", self.name, self.recovered_rows)

    # -- the log ----------------------------------------------------------------------------------
    def _recover(self) -> None:
        """After a restart: write what the previous incarnation logged, continue numbering."""
        last = 0
        for _, seg, state, path in _segments(self.run_dir, self.name):
            last = max(last, seg)
            hashes = {h for h, _ in read_segment(path)}
            if state == "wal":
                buffer: dict[str, list[dict[str, Any]]] = {}
                seen: set[str] = set()
                for h, rows_by_table in read_segment(path):
                    if h not in seen:
                        seen.add(h)
                        for table, rows in rows_by_table.items():
                            buffer.setdefault(table, []).extend(rows)
                written = _write_segment_parts(self.writer, seg, buffer)
                self._count(written)
                self.recovered_rows += sum(written.values())
                path.rename(_segment_path(self.run_dir, self.name, seg, "done"))
            self._hashes[seg] = hashes
            self._known_hashes |= hashes
        for p in self.run_dir.glob(f"*/part-{self.name}-*.parquet"):
            tail = p.stem.rsplit("-", 1)[-1]
            if tail.isdigit():
                last = max(last, int(tail))
        self.seg = last + 1

    def _count(self, written: Mapping[str, int]) -> None:
        for table, n in written.items():
            self.files_written += 1
            self.rows_written += n
            self.rows_by_table[table] = self.rows_by_table.get(table, 0) + n

    def _log(self, h: str, rows_by_table: Mapping[str, Sequence[dict[str, Any]]]) -> None:
        if self._wal_fh is None:
            path = _segment_path(self.run_dir, self.name, self.seg)
            path.parent.mkdir(parents=True, exist_ok=True)
            self._wal_fh = open(path, "ab")
        payload = pickle.dumps(
            {"h": h, "rows": {t: list(r) for t, r in rows_by_table.items() if r}}, protocol=pickle.HIGHEST_PROTOCOL
        )
        self._wal_fh.write(_HEADER.pack(len(payload), zlib.crc32(payload)) + payload)
        self._wal_fh.flush()  # in the kernel: survives a kill of this process

    def _retire(self) -> None:
        """The open segment's rows are in their parts: mark it done, drop old done ones."""
        if self._wal_fh is not None:
            self._wal_fh.close()
            self._wal_fh = None
        path = _segment_path(self.run_dir, self.name, self.seg)
        if path.exists():
            path.rename(_segment_path(self.run_dir, self.name, self.seg, "done"))
        self._hashes.setdefault(self.seg, set())
        self._retired_at[self.seg] = time.monotonic()
        self.seg += 1
        self._prune()

    def _prune(self) -> None:
        """Forget the segments this process retired that are neither among its last ``_KEEP_DONE``
        nor retired in the last ``_KEEP_DONE_S`` seconds: oldest first, stopping at the first one
        kept (retirement times only grow), so a flush costs what it forgets, not the window."""
        old = time.monotonic() - _KEEP_DONE_S
        while self._retired_at:
            seg, at = next(iter(self._retired_at.items()))
            if at > old or seg >= self.seg - _KEEP_DONE:
                return
            del self._retired_at[seg]
            self._known_hashes -= self._hashes.pop(seg, set())
            _segment_path(self.run_dir, self.name, seg, "done").unlink(missing_ok=True)

    def _known(self, h: str) -> bool:
        return h in self._known_hashes

    # -- input ----------------------------------------------------------------------------------
    def add(self, rows_by_table: Mapping[str, Sequence[dict[str, Any]]], flush: bool = False) -> int:
        """Add rows (already stamped with the run id); flushes when due (``flush``: now).
        Returns rows buffered.

        The rows are in the log before this returns; a batch seen before (a send retried
        after a restart of this actor) is acknowledged without being added again."""
        known = False
        if self.wal:
            h = batch_hash(rows_by_table)
            known = self._known(h)
            if not known:
                self._log(h, rows_by_table)
                self._hashes.setdefault(self.seg, set()).add(h)
                self._known_hashes.add(h)
        if not known:
            for table, rows in rows_by_table.items():
                if rows:
                    self._buffer.setdefault(table, []).extend(rows)
                    self._buffered += len(rows)
        if flush:
            self.flush()
        else:
            self.maybe_flush()
        return self._buffered

    def add_records(self, records: Iterable[Any], flush: bool = False) -> int:
        """Add typed records (grouped by table and stamped with the run id) like :meth:`add`; returns rows buffered."""
        return self.add(records_by_table(records, self.run_id), flush=flush)

    # -- output ---------------------------------------------------------------------------------
    def maybe_flush(self) -> int:
        """Flush when a buffer is due (``flush_rows`` rows, or rows older than ``flush_s`` seconds); returns the
        rows written, 0 when nothing was due."""
        if self._buffered >= self.flush_rows or (self._buffered and time.monotonic() - self._last_flush >= self.flush_s):
            return self.flush()
        return 0

    def flush(self) -> int:
        """Write every buffered row now; returns the number of rows written. A write that
        fails keeps the rows buffered (and logged) for the next flush."""
        n = self._buffered
        self._last_flush = time.monotonic()
        if not n:
            return 0
        t0 = time.perf_counter()
        written = _write_segment_parts(self.writer, self.seg, self._buffer)
        self._buffer, self._buffered = {}, 0
        self._count(written)
        if self.wal:
            self._retire()
        else:
            self.seg += 1
        self.write_seconds += time.perf_counter() - t0
        return n

    def close(self) -> int:
        """Flush, then remove this sink's log (the end of a session); returns rows flushed."""
        n = self.flush()
        if self._wal_fh is not None:
            self._wal_fh.close()
            self._wal_fh = None
        for _, _, state, path in _segments(self.run_dir, self.name):
            if state == "done":
                path.unlink(missing_ok=True)
        self._hashes.clear()
        self._known_hashes.clear()
        try:
            (self.run_dir / WAL_DIR).rmdir()
        except OSError:
            pass
        return n

    def ping(self) -> str:
        """The sink's name: the driver's liveness check (an answer after a restart counts)."""
        return self.name

    def pid(self) -> int:
        """The actor's process id (tests kill it to check durability)."""
        return os.getpid()

    def stats(self) -> dict[str, Any]:
        """Counters for the end-of-run summary and tests: rows and files written, rows buffered, write time, rows
        per table, rows recovered from the log, the current segment."""
        return {
            "rows_written": self.rows_written,
            "files_written": self.files_written,
            "rows_buffered": self._buffered,
            "write_seconds": self.write_seconds,
            "rows_by_table": dict(self.rows_by_table),
            "recovered_rows": self.recovered_rows,
            "segment": self.seg,
        }


class _SinkActor(Sink):
    """The sink as a Ray actor: the driver's log level first (:mod:`workers.log_setup`)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        configure_from_env()
        super().__init__(*args, **kwargs)


def sink_actor(runtime_env: dict | None = None, *, max_restarts: int | None = None) -> Any:
    """The Sink as a Ray actor (no CPU reservation: it mostly waits on the disk).

    Restartable, and its calls are retried on the new incarnation: a killed sink comes back
    (same arguments, same writer name, so it finds its log) and every sender - the episode
    workers waiting on an acknowledgement, the driver's terminal rows - goes on."""
    import ray  # Ray only where the actor is made: the sink's writer runs without a cluster

    restarts = SINK_MAX_RESTARTS if max_restarts is None else max_restarts
    options: dict[str, Any] = {"num_cpus": 0, "max_restarts": restarts, "max_task_retries": -1 if restarts else 0}
    if runtime_env:
        options["runtime_env"] = runtime_env
    return ray.remote(**options)(_SinkActor)
