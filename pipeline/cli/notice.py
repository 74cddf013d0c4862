"""A line on stderr when a step of a command runs longer than a moment, so a slow step is never silent.

``recap estimate`` imports litellm, opens environments and measures instances; each step is usually
quick, but a big sweep or a loaded machine can make one take many seconds. :func:`slow_notice` says
what is going on once the step has run ``after_s`` seconds (and how long it took when it ends),
and prints nothing for a step that ends before, nor to a stderr that is not a terminal.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TextIO

#: seconds a step may run before its line is printed
AFTER_S = 2.0


@contextmanager
def slow_notice(what: str, after_s: float = AFTER_S, stream: TextIO | None = None) -> Iterator[None]:
    """Run the block; when it is still running after ``after_s`` seconds, print ``recap: WHAT ...``
    on ``stream``, and ``recap: WHAT: done in N s`` when it ends. With no ``stream``: on stderr when
    it is a terminal, and nowhere when it is a file or a pipe, where the lines would be in the way of
    what a script reads there (a refusal is one line on stderr, whatever the machine's speed)."""
    if stream is None and not getattr(sys.stderr, "isatty", lambda: False)():
        yield
        return
    out = stream or sys.stderr
    started = time.monotonic()
    lock = threading.Lock()
    state = {"printed": False, "over": False}

    def say() -> None:
        with lock:
            if not state["over"]:
                print(f"recap: {what} ...", file=out, flush=True)
                state["printed"] = True

    timer = threading.Timer(after_s, say)
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        with lock:
            state["over"] = True
        timer.cancel()
        if state["printed"]:
            print(f"recap: {what}: done in {time.monotonic() - started:.1f} s", file=out, flush=True)
