"""Batched writer of the run's ``llm_calls`` rows (one per call, written by the gateway itself)
and of the gateway's ``events`` rows (failed attempts that are retried, calls that fail,
reservations of a dead gateway charged at restart).

Why batches: one Parquet part file per call would bury the run folder in tiny files, and a
part per minute would lose a minute of rows to a crash. Rows are flushed when ``max_rows``
are pending, at least every ``flush_interval_s`` (1 s) by :meth:`run_periodic_flush`, and on
close. Part files are atomic (:class:`schemas.parts.PartWriter`); a crash loses at most the
last second of rows - the budget itself is in the fsync'd ledger journal, not here.
"""

from __future__ import annotations

import asyncio
import json
import re
import threading
import time
import uuid
from pathlib import Path
from typing import Any

from schemas.kinds import EventKind, Severity
from schemas.parts import RUN_FILE, PartWriter, read_run_file
from schemas.records import CallRecord, EventRecord
from schemas.tables import check_vocabulary, record_to_row


class RunIdentityError(RuntimeError):
    """No run id given and the run folder has no readable run.json."""


def run_id_of(run_dir: Path | str) -> str:
    """The run id in ``RUN_DIR/run.json`` (written once by the pipeline)."""
    data = read_run_file(run_dir)
    if data is None or data.get("run_id") is None:
        why = "no readable run file" if data is None else "no run_id in it"
        raise RunIdentityError(f"pass run_id or create {Path(run_dir) / RUN_FILE} with a run_id ({why})")
    return str(data["run_id"])


def writer_name(deployment: str) -> str:
    """A part-file writer name for one gateway of ``deployment``: a slug of the name plus a random
    suffix, so a restarted gateway never shares a name with its predecessor."""
    slug = re.sub(r"[^A-Za-z0-9]+", "-", deployment).strip("-")[:40] or "gateway"
    return f"gw-{slug}-{uuid.uuid4().hex[:6]}"


class CallLog:
    """Buffers one gateway's ``llm_calls`` and ``events`` rows and writes them as part files in
    batches (see the module docstring for when)."""

    def __init__(self, run_dir: Path | str, run_id: str, writer: str, *, max_rows: int = 256, flush_interval_s: float = 1.0):
        self.run_id = run_id
        self.flush_interval_s = flush_interval_s
        self.max_rows = max_rows
        self._writer = PartWriter(Path(run_dir), writer=writer)
        self._pending: list[dict[str, Any]] = []
        self._events: list[dict[str, Any]] = []
        self._write_lock = threading.Lock()
        self.rows_written = 0
        self.events_written = 0

    def add(self, record: CallRecord) -> None:
        self._pending.append(record_to_row(record, self.run_id))
        if len(self._pending) >= self.max_rows:
            self.flush()

    def add_event(self, kind: EventKind, severity: Severity, detail: dict[str, Any], episode_id: str | None = None) -> None:
        """A gateway ``events`` row (``source="gateway"``), written with the next batch.

        ``unit_id`` stays empty: resume reads attempt numbers from events that name a unit,
        and a call attempt is not a unit attempt."""
        self._events.append(
            record_to_row(
                check_vocabulary(
                    EventRecord(
                        ts=time.time(),
                        source="gateway",
                        kind=kind,
                        severity=severity,
                        episode_id=episode_id,
                        detail=json.dumps(detail, sort_keys=True, default=str),
                    )
                ),
                self.run_id,
            )
        )
        if len(self._events) >= self.max_rows:
            self.flush()

    def flush(self) -> None:
        rows, self._pending = self._pending, []
        events, self._events = self._events, []
        if rows:
            self._write(rows)
        if events:
            self._write_events(events)

    async def run_periodic_flush(self) -> None:
        """Flush every ``flush_interval_s`` until cancelled (then flush once more).

        A batch being written when the task is cancelled is waited for before the task ends:
        the rows were already taken off the buffer, and the thread writing them cannot be
        cancelled, so a caller that awaited this task and then ended the process (the gateway's
        close, then ``ray.kill``) would otherwise lose them."""
        try:
            while True:
                await asyncio.sleep(self.flush_interval_s)
                rows, self._pending = self._pending, []
                if rows:
                    await _finish(asyncio.ensure_future(asyncio.to_thread(self._write, rows)))
                events, self._events = self._events, []
                if events:
                    await _finish(asyncio.ensure_future(asyncio.to_thread(self._write_events, events)))
        finally:
            self.flush()

    def _write(self, rows: list[dict[str, Any]]) -> None:
        with self._write_lock:
            self._writer.write_rows(CallRecord.table, rows)
            self.rows_written += len(rows)

    def _write_events(self, rows: list[dict[str, Any]]) -> None:
        with self._write_lock:
            self._writer.write_rows(EventRecord.table, rows)
            self.events_written += len(rows)

    @property
    def pending(self) -> int:
        return len(self._pending)


async def _finish(write: asyncio.Future) -> None:
    """Await ``write``; when cancelled meanwhile, still wait for it to end, then pass the
    cancellation on (the write is a thread: it goes on either way, and must end before we do)."""
    try:
        await asyncio.shield(write)
    except asyncio.CancelledError:
        await asyncio.wait([write])
        raise
