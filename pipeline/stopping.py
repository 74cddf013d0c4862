"""Ctrl-C and SIGTERM during a driver session: a graceful stop first, an immediate one on demand.

Why not Python's default (``KeyboardInterrupt`` wherever the main thread happens to be): raised
between collecting an attempt and sending its terminal row, it loses a finished - and paid -
episode, and it cuts every episode in flight, whose calls were paid for and are then paid again
by the resume. So, once the session's loop runs (:meth:`StopRequests.arm`):

* the first SIGINT or SIGTERM asks for a *graceful* stop: no unit is started any more, the
  episodes in flight finish (their rows and calls recorded) for up to ``grace_s`` seconds
  (:data:`DEFAULT_GRACE_S`, ``recap run --stop-grace``), then everything is written and the
  command exits 130 naming ``recap resume``. SIGTERM is treated like Ctrl-C because that is
  what a scheduler or ``systemctl stop`` sends before it kills.
* the second asks to stop *now*: the episodes in flight are cut (their workers stopped, no new
  call starts); the calls they had completed are in the ledger journal and the ``llm_calls``
  table, one still at the provider stays charged at its worst case, and the resume runs those
  units again under a new attempt number;
* a third raises ``KeyboardInterrupt`` at once (the session's ``finally`` blocks still run).

Before the loop runs (Ray starting, actors starting) any signal raises ``KeyboardInterrupt``:
nothing has been paid yet. The handlers only set flags (no printing in a signal handler); the
session's loop, which wakes at least every half second, acts on them.
"""

from __future__ import annotations

import os
import signal
import threading
from types import FrameType
from typing import Any

#: seconds a graceful stop waits for the episodes in flight before it cuts them
DEFAULT_GRACE_S = 60.0
_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopRequests:
    """Counts SIGINT/SIGTERM while installed (:meth:`install` / :meth:`restore`, main thread
    only; elsewhere it stays inert and the default behaviour applies)."""

    def __init__(self) -> None:
        self.count = 0
        self.armed = False
        self._previous: dict[int, Any] = {}
        self._pipe: tuple[int, int] | None = None
        self._previous_fd = -1

    def install(self) -> None:
        """Take over SIGINT and SIGTERM (a no-op off the main thread); again after ``ray.init``,
        which sets a SIGTERM handler of its own (``sys.exit``).

        Python runs a handler once for all the deliveries of a signal that arrived while the
        main thread sat in one blocking call (a quick double Ctrl-C during a ``ray.wait``), so
        the deliveries are counted from a wakeup pipe, which gets one byte per delivery."""
        if threading.current_thread() is not threading.main_thread():
            return
        for sig in _SIGNALS:
            previous = signal.signal(sig, self._handle)
            self._previous.setdefault(sig, previous)
        if self._pipe is None:
            r, w = os.pipe()
            os.set_blocking(r, False)
            os.set_blocking(w, False)
            try:
                self._previous_fd = signal.set_wakeup_fd(w, warn_on_full_buffer=False)
            except ValueError:
                os.close(r)
                os.close(w)
                return
            self._pipe = (r, w)

    def restore(self) -> None:
        """Give SIGINT and SIGTERM back to their previous handlers."""
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        self._previous.clear()
        if self._pipe is not None:
            signal.set_wakeup_fd(self._previous_fd)
            for fd in self._pipe:
                os.close(fd)
            self._pipe = None
        self.armed = False

    def _deliveries(self) -> int:
        """SIGINT/SIGTERM deliveries since the last handler call (at least the current one)."""
        n = 0
        if self._pipe is not None:
            try:
                while chunk := os.read(self._pipe[0], 512):
                    n += sum(1 for b in chunk if b in _SIGNALS)
            except BlockingIOError:
                pass
            except OSError:
                pass
        return max(1, n)

    def arm(self) -> None:
        """From now on the first two signals only set flags (the session's loop runs)."""
        self.armed = True

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        self.count += self._deliveries()
        if not self.armed or self.count >= 3:
            raise KeyboardInterrupt

    @property
    def graceful(self) -> bool:
        """A stop was asked for: start nothing new."""
        return self.count >= 1

    @property
    def now(self) -> bool:
        """An immediate stop was asked for: cut what is in flight."""
        return self.count >= 2
