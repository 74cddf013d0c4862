"""fast-downward's PDDL -> SAS translation, done once per (domain, problem) in a process.

Why: textworld builds a ``PddlState`` for every reset of an ALFWorld game - two of them per
reset (``textworld/envs/pddl/pddl.py`` ``reset``, then ``load``) - and each translates the game's
domain and problem twice (``textworld/envs/pddl/logic/__init__.py``, ``PddlState.__init__``: once
as is, once optimised for replanning). The translation is a pure function of the two texts and
the flag, yet it is ~90 % of a reset's CPU (about 3.5 s per reset on this machine). Cached here,
a game's first reset translates twice and every later reset of it (the demonstration's replay,
``recap env play``, a retried attempt in the same worker) not at all.

Each caller gets its own deep copy of the translated task (textworld keeps and may change it);
the SAS text is an immutable string. The translation itself runs under a lock: fast-downward
configures it through module-level options (and ``sys.argv``), which two threads translating
at once - several episodes in one worker process - would race on.
"""

from __future__ import annotations

import copy
import hashlib
import threading
from collections import OrderedDict
from typing import Any

#: translated (domain, problem, optimize) kept per process (the games in play and a few more)
CACHE_SIZE = 16


class TranslationCache:
    """A memo in front of ``fast_downward.pddl2sas`` (see the module docstring)."""

    def __init__(self, size: int = CACHE_SIZE) -> None:
        self.size = size
        self.translations = 0  # misses: translations actually run
        self._done: OrderedDict[tuple[str, str, bool], tuple[Any, str]] = OrderedDict()
        self._lock = threading.Lock()

    def translate(
        self, original: Any, domain: str, problem: str, verbose: bool = False, optimize: bool = False
    ) -> tuple[Any, str]:
        key = (hashlib.sha256(domain.encode()).hexdigest(), hashlib.sha256(problem.encode()).hexdigest(), bool(optimize))
        with self._lock:
            hit = self._done.get(key)
            if hit is None:
                self.translations += 1
                hit = original(domain, problem, verbose=verbose, optimize=optimize)
                self._done[key] = hit
                while len(self._done) > self.size:
                    self._done.popitem(last=False)
            else:
                self._done.move_to_end(key)
            task, sas = hit
            return copy.deepcopy(task), sas

    def install(self) -> None:
        """Put the memo in front of ``fast_downward.pddl2sas`` (once per process)."""
        try:
            import fast_downward
        except ImportError:  # textworld reports the missing planner itself when a game starts
            return
        with self._lock:
            if getattr(fast_downward.pddl2sas, "_memo", None) is not None:
                return
            original = fast_downward.pddl2sas

            def pddl2sas(domain: str, problem: str, verbose: bool = False, optimize: bool = False) -> tuple[Any, str]:
                return self.translate(original, domain, problem, verbose=verbose, optimize=optimize)

            pddl2sas._memo = self  # type: ignore[attr-defined]
            fast_downward.pddl2sas = pddl2sas


TRANSLATIONS = TranslationCache()
