"""An append-only JSON-lines journal: written at once, fsync'd where it matters, single writer.

Why: the budget must survive a killed process *exactly*. Every entry is written to the file
(``write`` + ``flush``) before :meth:`Journal.append` returns, which is all a process kill
needs - the kernel keeps the data. Against a machine crash, an entry appended with
``sync=True`` (a budget reservation, before its request is sent) is ``fdatasync``'d before
the call returns; other entries (settlements) are synced by the next synced append, by a
sync at least every ``sync_interval_s`` while entries keep coming, and on close - a machine
crash can only leave a settlement unsynced, which a restart then charges at its (higher)
reserved amount, so caps still hold. The sync runs inline: a thread hand-off costs more than
the fdatasync itself on a busy machine. A crash can only tear the last line, which replay
drops (and truncates away, so later appends stay parseable), keeping the dropped bytes in a
``<journal>.torn-<time>`` file beside it for the record; a torn line may hold anything - a
prefix of an entry, garbage, the zero bytes a machine crash leaves. A bad line *before* the
last one is not a crash's tear: replay refuses it (:class:`JournalError`, naming the file and
the line) rather than guess the spend. An exclusive ``flock`` keeps two
live ledgers off one run folder; the kernel releases it when its process dies, so a restart
after ``kill -9`` just works.

Group commit (:meth:`Journal.commit`): an asyncio caller that appends with ``sync=False`` and
then awaits ``commit()`` is released once an ``fdatasync`` that started after its append has
returned - the same promise as ``sync=True`` - but every caller that appended within the same
event-loop tick shares that one ``fdatasync``. Why: an fsync per reservation costs 1-4 ms on
a shared disk and serialises concurrent callers behind one another; a batch costs one. The
sync still runs inline on the loop (a thread hand-off costs more than the fdatasync on a busy
machine, and the loop has nothing else it may do with those reservations meanwhile).
"""

from __future__ import annotations

import asyncio
import fcntl
import json
import os
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any


class JournalError(RuntimeError):
    """The journal is locked by another live ledger, or corrupt before its last line."""


@dataclass(frozen=True)
class BadLine:
    """The first line of a journal's bytes that is not a complete entry: ``line`` (1-based, as
    an editor shows it) of ``lines``; ``torn`` when nothing but blanks or zero bytes follow it
    (a crash mid-write: safe to cut at ``good_end``), else corrupt in the middle; ``size`` of
    the bytes scanned."""

    line: int
    lines: int
    torn: bool
    good_end: int
    size: int


def _entry_ok(line: bytes) -> bool:
    try:
        return isinstance(json.loads(line), dict)
    except ValueError:  # JSONDecodeError, UnicodeDecodeError (garbage or zero-filled bytes)
        return False


def _blank(line: bytes) -> bool:
    return not line.strip(b" \t\r\n\x00")


def scan(data: bytes) -> BadLine | None:
    """The first line of ``data`` (a journal's bytes, read without opening a :class:`Journal`)
    that is not a complete entry, or None: what ``recap status`` reports and ``--repair`` cuts."""
    lines = data.split(b"\n")
    n_lines = len(lines) - (1 if data.endswith(b"\n") else 0)
    good_end = 0
    for i, line in enumerate(lines):
        last = i == len(lines) - 1
        if not line.strip(b" \t\r") or _entry_ok(line):  # an entry, or plain whitespace
            good_end += len(line) + (0 if last else 1)
            continue
        torn = all(_blank(r) for r in lines[i + 1 :])
        return BadLine(i + 1, max(n_lines, i + 1), torn, good_end, len(data))
    return None


class Journal:
    """The budget ledger's append-only journal file (see the module docstring). Opening takes the
    file's exclusive lock, waiting up to ``lock_timeout_s`` (then JournalError); ``fsync=False``
    never syncs."""

    def __init__(self, path: Path | str, *, fsync: bool = True, lock_timeout_s: float = 10.0, sync_interval_s: float = 1.0):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fsync = fsync
        self._fh = open(self.path, "a+b")
        # a killed predecessor may take a moment to exit (and release the lock): wait a little
        deadline = time.monotonic() + lock_timeout_s
        while True:
            try:
                fcntl.flock(self._fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() >= deadline:
                    self._fh.close()
                    raise JournalError(
                        f"{self.path} is held by another live ledger (one budget authority per run folder)"
                    ) from None
                time.sleep(0.05)
        self.sync_interval_s = sync_interval_s
        self._last_sync = time.monotonic()
        self._dirty = False
        #: entries written so far, and how many of them an fdatasync has put on disk
        self.written = 0
        self.synced = 0
        #: fdatasync calls made (figures for benches and the group-commit tests)
        self.syncs = 0
        self._batch: asyncio.Future | None = None  # the commit scheduled for this loop tick

    @staticmethod
    def _parse(line: bytes) -> dict[str, Any] | None:
        """The entry of a line, or None when the line is not one (torn, garbage, not an object)."""
        try:
            entry = json.loads(line)
        except ValueError:  # JSONDecodeError, and UnicodeDecodeError for garbage / zero bytes
            return None
        return entry if isinstance(entry, dict) else None

    def replay(self) -> Iterator[dict[str, Any]]:
        """Every complete entry in order; a torn last line is cut off the file (its bytes kept
        in a ``.torn-`` file beside it)."""
        self._fh.seek(0)
        data = self._fh.read()
        lines = data.split(b"\n")
        good_end = 0
        for i, line in enumerate(lines):
            is_last = i == len(lines) - 1
            if not line.strip():
                good_end += len(line) + (0 if is_last else 1)
                continue
            entry = self._parse(line)
            if entry is None:
                if any(rest.strip(b" \t\r\n\x00") for rest in lines[i + 1 :]):
                    raise JournalError(
                        f"{self.path}: line {i + 1} is corrupt and not the last one; "
                        "the spend cannot be restored from it (restore the file from a backup)"
                    )
                break
            if is_last:  # complete JSON cut just before its newline
                self._fh.seek(0, os.SEEK_END)
                self._fh.write(b"\n")
                self._fh.flush()
                good_end = len(data) + 1
                yield entry
                break
            good_end += len(line) + 1
            yield entry
        if good_end < len(data):
            self._keep_torn(data[good_end:])
            self._fh.truncate(good_end)
            self._fh.flush()

    def _keep_torn(self, torn: bytes) -> None:
        """The bytes a replay cuts away, kept beside the journal (best effort)."""
        if not torn.strip(b" \t\r\n\x00"):
            return
        try:
            stamp = time.strftime("%Y%m%dT%H%M%S", time.gmtime())
            dest = self.path.with_name(f"{self.path.name}.torn-{stamp}-{os.getpid()}")
            with open(dest, "ab") as fh:
                fh.write(torn)
                fh.flush()
                os.fsync(fh.fileno())
        except OSError:
            pass

    def append(self, entry: dict[str, Any], *, sync: bool = False) -> int:
        """Write one entry now; with ``sync`` also put it on disk before returning. Returns the
        entry's sequence number (1, 2, ...), which :meth:`commit` covers once durable."""
        self._fh.seek(0, os.SEEK_END)
        self._fh.write(json.dumps(entry, separators=(",", ":"), ensure_ascii=False).encode() + b"\n")
        self._fh.flush()
        self._dirty = True
        self.written += 1
        seq = self.written
        if self._fsync and (sync or time.monotonic() - self._last_sync >= self.sync_interval_s):
            self.sync()
        return seq

    def sync(self) -> None:
        """Put every entry written so far on disk (one ``fdatasync``)."""
        if self._fh.closed:
            return
        upto = self.written  # entries written after this line may or may not be covered
        if self._dirty:
            self._dirty = False
            try:
                os.fdatasync(self._fh.fileno())
            except BaseException:
                self._dirty = True
                raise
            self.syncs += 1
            self._last_sync = time.monotonic()
        self.synced = max(self.synced, upto)

    async def commit(self, seq: int | None = None) -> None:
        """Return once entry ``seq`` (default: every entry written so far) is on disk.

        Callers that wait within the same event-loop tick share one ``fdatasync``: the first
        schedules it with ``call_soon`` (after the other ready callbacks of the tick, which may
        append too), the others await the same future. Without fsync (``fsync=False``) there
        is nothing to wait for. A failed fdatasync raises in every waiter of its batch."""
        target = self.written if seq is None else seq
        if not self._fsync:
            return
        loop = asyncio.get_running_loop()
        while self.synced < target:
            if self._fh.closed:
                raise JournalError(f"{self.path} was closed before entry {target} was committed")
            batch = self._batch
            if batch is None or batch.done() or batch.get_loop() is not loop:
                batch = self._batch = loop.create_future()
                loop.call_soon(self._commit_batch, batch)
            # shielded: a cancelled waiter must not cancel the batch the others wait for
            await asyncio.shield(batch)

    def _commit_batch(self, batch: asyncio.Future) -> None:
        if self._batch is batch:
            self._batch = None
        if batch.done():
            return
        try:
            self.sync()
        except BaseException as exc:
            batch.set_exception(exc)
            batch.exception()  # retrieved here: waiters that were cancelled never look
        else:
            batch.set_result(None)

    def close(self) -> None:
        if self._fh.closed:
            return
        if self._fsync:
            self.sync()
        self._fh.close()  # closing the file releases the lock
