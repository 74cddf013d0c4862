"""The viewer's current snapshot, rebuilt in a background thread when the run folders' part files change.

:class:`Catalog` watches the table folders (names, sizes and times of the part files) and builds
a new snapshot in a background thread when they change, so a page shows rows that a running
sweep wrote a moment ago without waiting for the rebuild.
"""

from __future__ import annotations

import logging
import os
import threading
from collections.abc import Sequence
from pathlib import Path

from reports.sections import PLAN_FILE
from reports.views import scan_runs
from reports.webview.search import SearchIndex
from reports.webview.snapshot import Snapshot, build_snapshot
from schemas.parts import RUN_FILE
from schemas.tables import TABLES

log = logging.getLogger(__name__)


def _fingerprint(run_dirs: Sequence[Path]) -> tuple:
    """Names, sizes and times of every part file and run file: changes when a part lands."""
    out: list[tuple[str, int, int]] = []
    for d in run_dirs:
        for table in TABLES:
            folder = d / table
            try:
                with os.scandir(folder) as it:
                    out.extend(
                        (e.path, e.stat().st_size, e.stat().st_mtime_ns)
                        for e in it
                        if e.name.endswith(".parquet") and not e.name.startswith(".")
                    )
            except OSError:
                continue
        for name in (RUN_FILE, PLAN_FILE):
            try:
                st = (d / name).stat()
                out.append((str(d / name), st.st_size, st.st_mtime_ns))
            except OSError:
                pass
    return tuple(sorted(out))


class Catalog:
    """The current snapshot of ``run_dirs`` and a background refresher (``poll_s`` > 0)."""

    def __init__(self, run_dirs: Sequence[str | Path], *, poll_s: float = 2.0) -> None:
        self.run_dirs, _, _ = scan_runs(run_dirs)  # validates the folders (RunDirError)
        self._index = SearchIndex()
        self._print = _fingerprint(self.run_dirs)
        self._snap = build_snapshot(self.run_dirs, self._index)
        self._swap = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        if poll_s > 0:
            self._thread = threading.Thread(target=self._poll, args=(poll_s,), name="recap-view-refresh", daemon=True)
            self._thread.start()

    @property
    def snap(self) -> Snapshot:
        """The snapshot to query now; the refresher swaps it whole, so a caller keeps a consistent one."""
        return self._snap

    def refresh(self) -> bool:
        """Rebuild when the part files changed; True when a new snapshot is in place."""
        with self._swap:
            fp = _fingerprint(self.run_dirs)
            if fp == self._print:
                return False
            new = build_snapshot(self.run_dirs, self._index)
            old, self._snap, self._print = self._snap, new, fp
        old.close()
        return True

    def _poll(self, every: float) -> None:
        while not self._stop.wait(every):
            try:
                self.refresh()
            except Exception as exc:  # noqa: BLE001 - a half-written folder: keep the last snapshot
                log.warning("recap view: refresh failed, keeping the last snapshot: %s", exc)

    def close(self) -> None:
        """Stop the refresher (waiting up to 5 s) and close the current snapshot."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        self._snap.close()
