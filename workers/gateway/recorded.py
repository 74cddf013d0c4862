"""The budget ledger's recorded responses, kept on disk: memory that stays flat over a long run.

Why: the ledger answers a repeated ``call_key`` with the response it recorded (idempotency: an
episode replayed after a crash gets the answers its first attempt paid for) and, when asked,
a repeated request fingerprint with a cached response. It kept every response in a dict, so
the budget actor grew with every call of the run (about 1 MB a minute at 30 calls/s in
bench/soak.py: a response and its key each time), for lookups that happen only on retries.

Here they live in a private temporary SQLite database (``sqlite3.connect("")``: a file SQLite
creates, holds at most ``cache_kib`` of in memory and deletes when the connection closes).
It needs no durability of its own: the journal is the record, and a ledger that restarts
fills a fresh one while it replays the journal (:meth:`BudgetLedger._restore`) - so a
repeated call_key is still answered after a restart, and nothing is added to the run folder.

Not thread-safe by itself: the ledger calls it under its own lock.
"""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Iterator
from typing import Any

#: rows written per transaction (a commit to a temporary database writes pages, never fsyncs)
COMMIT_EVERY = 256


class RecordedResults:
    """A ``key -> response`` map (``in``, ``[]``, ``[]=``, ``len``) whose memory is bounded by
    SQLite's page cache, not by the number of entries."""

    def __init__(self, cache_kib: int = 1024):
        self._db = sqlite3.connect("", isolation_level=None, check_same_thread=False)
        self._db.execute(f"PRAGMA cache_size=-{int(cache_kib)}")
        self._db.execute("PRAGMA journal_mode=OFF")
        self._db.execute("PRAGMA synchronous=OFF")
        self._db.execute("CREATE TABLE recorded (key TEXT PRIMARY KEY, result TEXT NOT NULL) WITHOUT ROWID")
        self._pending = 0
        #: kept here, not counted in SQL: ``len`` (the ledger's stats) must answer after close too
        self._count = 0

    def __contains__(self, key: object) -> bool:
        return self._db.execute("SELECT 1 FROM recorded WHERE key = ?", (key,)).fetchone() is not None

    def __getitem__(self, key: str) -> dict[str, Any]:
        row = self._db.execute("SELECT result FROM recorded WHERE key = ?", (key,)).fetchone()
        if row is None:
            raise KeyError(key)
        return json.loads(row[0])

    def __setitem__(self, key: str, result: dict[str, Any]) -> None:
        if not self._pending:
            self._db.execute("BEGIN")
        text = json.dumps(result, separators=(",", ":"), ensure_ascii=False)
        if self._db.execute("INSERT OR IGNORE INTO recorded VALUES (?, ?)", (key, text)).rowcount == 1:
            self._count += 1
        else:
            self._db.execute("UPDATE recorded SET result = ? WHERE key = ?", (text, key))
        self._pending += 1
        if self._pending >= COMMIT_EVERY:
            self._commit()

    def __iter__(self) -> Iterator[str]:
        """The keys, in key order (a starting gateway shard asks which calls are recorded)."""
        return iter([row[0] for row in self._db.execute("SELECT key FROM recorded ORDER BY key")])

    def __len__(self) -> int:
        return self._count

    def _commit(self) -> None:
        if self._pending:
            self._db.execute("COMMIT")
            self._pending = 0

    def close(self) -> None:
        """Drop the database (SQLite deletes its file); ``len`` still answers."""
        self._commit()
        self._db.close()
