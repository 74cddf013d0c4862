"""What a run folder says is done, and the queue of what is left.

Resume reads everything from the tables, never from the driver's memory: a unit is *completed*
when it has a terminal ``episodes`` row whose end reason is not ``budget_exhausted`` (an episode
cut by a cap is unfinished work that a resume with a higher cap continues). Attempt numbers
continue after the highest attempt seen anywhere (episode rows, events, the episode ids of
rows a crashed attempt already wrote, and the call keys of the gateway's ledger journal - an
attempt killed within a second of its calls has no rows yet, only journal lines), so a new
attempt never shares an ``episode_id`` with an old one (nor its call keys, which the ledger
would otherwise answer with the killed attempt's recorded replies). Only attempts that *failed* (worker lost, worker error) count against
``max_attempts``; an attempt cut short by a driver crash does not.
"""

from __future__ import annotations

import json
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from pipeline.store import RunStore
from pipeline.units import Unit
from workers.gateway.ledger import JOURNAL_NAME
from workers.storage import BadPart

#: event kinds that record a failed attempt of a unit
FAILED_ATTEMPT_EVENTS = ("worker_lost", "attempt_failed")
_ID_TABLES = ("messages", "steps", "tree_nodes", "llm_calls")
#: the gateway's budget journal, relative to the run folder
JOURNAL_FILE = JOURNAL_NAME


def parse_episode_id(episode_id: str) -> tuple[str, int] | None:
    unit, sep, attempt = episode_id.rpartition("-")
    if not sep or not attempt.isdigit():
        return None
    return unit, int(attempt)


@dataclass
class RunState:
    completed: set[str] = field(default_factory=set)
    budget_stopped: set[str] = field(default_factory=set)
    last_attempt: dict[str, int] = field(default_factory=dict)
    failures: dict[str, int] = field(default_factory=dict)
    terminal_rows: int = 0
    bad_parts: list[BadPart] = field(default_factory=list)

    def _seen(self, unit_id: str, attempt: int) -> None:
        if attempt > self.last_attempt.get(unit_id, 0):
            self.last_attempt[unit_id] = attempt


def load_state(store: RunStore) -> RunState:
    state = RunState()
    eps, bad = store.read_table("episodes", ["unit_id", "attempt", "end_reason"])
    state.bad_parts += bad
    state.terminal_rows = eps.num_rows
    for unit_id, attempt, reason in zip(*(eps.column(c).to_pylist() for c in ("unit_id", "attempt", "end_reason"))):
        state._seen(unit_id, attempt)
        if reason == "budget_exhausted":
            state.budget_stopped.add(unit_id)
        else:
            state.completed.add(unit_id)
    state.budget_stopped -= state.completed
    events, bad = store.read_table("events", ["kind", "unit_id", "detail"])
    state.bad_parts += bad
    for kind, unit_id, detail in zip(*(events.column(c).to_pylist() for c in ("kind", "unit_id", "detail"))):
        if not unit_id:
            continue
        try:
            attempt = int(json.loads(detail or "{}").get("attempt", 0))
        except (ValueError, TypeError, AttributeError):
            attempt = 0
        state._seen(unit_id, attempt)
        if kind in FAILED_ATTEMPT_EVENTS:
            state.failures[unit_id] = state.failures.get(unit_id, 0) + 1
    for table in _ID_TABLES:
        ids, bad = store.read_table(table, ["episode_id"])
        state.bad_parts += bad
        for eid in set(ids.column("episode_id").to_pylist()):
            parsed = parse_episode_id(eid or "")
            if parsed:
                state._seen(*parsed)
    for eid in journal_episode_ids(store):
        parsed = parse_episode_id(eid)
        if parsed:
            state._seen(*parsed)
    return state


def journal_episode_ids(store: RunStore) -> set[str]:
    """Episode ids named by the call keys (``<episode_id>#<call>``) of the ledger journal."""
    text = store.read_text(JOURNAL_FILE)
    out: set[str] = set()
    for line in (text or "").splitlines():
        try:
            key = json.loads(line).get("key")
        except (ValueError, AttributeError):
            continue  # a torn last line
        if isinstance(key, str) and "#" in key:
            out.add(key.rsplit("#", 1)[0])
    return out


@dataclass
class Pending:
    unit: Unit
    attempt: int


class UnitQueue:
    """Units still to run, in plan order; retried units go to the back."""

    def __init__(self, units: Iterable[Unit], state: RunState) -> None:
        self._q: deque[Pending] = deque()
        self.last_attempt = dict(state.last_attempt)
        for u in units:
            if u.unit_id not in state.completed:
                self._q.append(Pending(u, self.last_attempt.get(u.unit_id, 0) + 1))

    def __len__(self) -> int:
        return len(self._q)

    def take(self, allowed: Callable[[Unit], bool] = lambda u: True) -> Pending | None:
        """The first pending unit that ``allowed`` accepts (e.g. whose model is under its cap)."""
        for i, p in enumerate(self._q):
            if allowed(p.unit):
                del self._q[i]
                self.last_attempt[p.unit.unit_id] = max(self.last_attempt.get(p.unit.unit_id, 0), p.attempt)
                return p
        return None

    def retry(self, unit: Unit) -> Pending:
        p = Pending(unit, self.last_attempt.get(unit.unit_id, 0) + 1)
        self._q.append(p)
        return p

    def units(self) -> list[Unit]:
        return [p.unit for p in self._q]
