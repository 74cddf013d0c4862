"""What a run folder says is done, and the queue of what is left.

Resume reads everything from the tables, never from the driver's memory: a unit is *completed*
when it has a terminal ``episodes`` row whose end reason is neither ``budget_exhausted`` (an
episode cut by a cap is unfinished work that a resume with a higher cap continues) nor an
*infrastructure failure* (:func:`infra_failure`: end reason ``infra_error`` - a failed model
service (connection, auth, rate limit, timeout, server error, not found) or a unit the driver
gave up on after its workers died or its client failed; runs of schema version 1 wrote these as
``llm_error``/``env_error`` and the same rule recognises them from the row's error). Such a unit is *retryable*: the next ``recap
resume`` (or ``recap run`` of the same sweep, e.g. with the ``api_base`` corrected) runs it
again under the next attempt number; its earlier rows stay for the record, and its failed
attempts before that row no longer count against ``max_attempts``. Attempt numbers
continue after the highest attempt seen anywhere (episode rows, events, the episode ids of
rows a crashed attempt already wrote, and the call keys of the gateway's ledger journal - an
attempt killed within a second of its calls has no rows yet, only journal lines), so a new
attempt never shares an ``episode_id`` with an old one (nor its call keys, which the ledger
would otherwise answer with the killed attempt's recorded replies). Only attempts that *failed* (worker lost, worker error) count against
``max_attempts``; an attempt cut short by a driver crash does not.

``recap resume RUN --retry errors`` (``retry="errors"``, see :data:`RETRY_MODES`) re-runs, on
top, every unit whose latest completing row ended ``env_error`` or ``llm_error`` of any kind (a
data folder fixed since, a ``bad_request`` fixed by a param change, an agent crash the driver
gave up on): :func:`load_state` counts them as not completed (``RunState.errored``), so they
are queued under the next attempt number like an infrastructure failure, their earlier rows
kept for the record. Without it (``retry="infra"``, the default) only infrastructure failures
are retried.
"""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import time
from collections import deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Literal

from pipeline.errors import RunFolderError
from pipeline.store import RunStore
from pipeline.units import Unit
from schemas.labels import GAVE_UP_PREFIX, INFRA_ERROR, INFRA_ERROR_KINDS, infra_failure
from schemas.parts import BadPart
from workers.gateway import entries
from workers.gateway.entries import AttemptSpend, LedgerKeyError
from workers.gateway.journal import scan
from workers.gateway.ledger import JOURNAL_NAME

#: event kinds that record a failed attempt of a unit
FAILED_ATTEMPT_EVENTS = ("worker_lost", "attempt_failed")
_ID_TABLES = ("messages", "steps", "tree_nodes", "llm_calls", "tool_calls")
#: the gateway's budget journal, relative to the run folder
JOURNAL_FILE = JOURNAL_NAME


# the rule itself lives with the row labels (schemas.labels), so that the reader of an old
# part derives ``infra_error`` by the same rule; it is re-exported here for the pipeline
__all__ = ["GAVE_UP_PREFIX", "INFRA_ERROR", "INFRA_ERROR_KINDS", "AttemptSpend", "infra_failure"]


#: what a resume re-runs besides unfinished units: ``infra`` - units whose latest row is an
#: infrastructure failure (always); ``errors`` - also units that ended ``env_error``/``llm_error``
Retry = Literal["infra", "errors"]
RETRY_MODES: tuple[str, ...] = ("infra", "errors")
#: end reasons ``--retry errors`` re-runs
ERROR_END_REASONS = ("env_error", "llm_error")


def is_final(end_reason: str | None, error: str | None) -> bool:
    """A terminal row that completes its unit (not cut by a cap, not an infrastructure failure)."""
    return end_reason != "budget_exhausted" and infra_failure(end_reason, error) is None


def parse_episode_id(episode_id: str) -> tuple[str, int] | None:
    unit, sep, attempt = episode_id.rpartition("-")
    if not sep or not attempt.isdigit():
        return None
    return unit, int(attempt)


@dataclass
class RunState:
    completed: set[str] = field(default_factory=set)
    budget_stopped: set[str] = field(default_factory=set)
    #: unit -> the infrastructure failure its latest terminal row records (retryable)
    infra_failed: dict[str, str] = field(default_factory=dict)
    last_attempt: dict[str, int] = field(default_factory=dict)
    failures: dict[str, int] = field(default_factory=dict)
    terminal_rows: int = 0
    bad_parts: list[BadPart] = field(default_factory=list)
    #: unit -> the end reason (env_error / llm_error) of its latest completing row; with
    #: ``retry="errors"`` these units are not in ``completed`` (they run again)
    errored: dict[str, str] = field(default_factory=dict)
    #: what this state was read for (see :data:`Retry`)
    retry: str = "infra"

    def _seen(self, unit_id: str, attempt: int) -> None:
        if attempt > self.last_attempt.get(unit_id, 0):
            self.last_attempt[unit_id] = attempt


def load_state(store: RunStore, retry: Retry = "infra") -> RunState:
    """What the run folder says is done. ``retry="errors"``: units whose latest completing row
    ended ``env_error``/``llm_error`` count as not completed (listed in ``errored``), so a
    resume runs them again."""
    if retry not in RETRY_MODES:
        raise ValueError(f"retry must be one of {', '.join(RETRY_MODES)}, got {retry!r}")
    state = RunState(retry=retry)
    ended = _read_episodes(store, state)
    _read_failure_events(store, state, ended)
    _read_attempt_ids(store, state)
    return state


def _read_episodes(store: RunStore, state: RunState) -> dict[str, int]:
    """The terminal rows into ``state`` (completed, errored, budget-stopped, infrastructure
    failures); per unit the highest attempt of any terminal row (failures before it are spent)."""
    cols = ("unit_id", "attempt", "end_reason", "error")
    eps, bad = store.read_table("episodes", list(cols))
    state.bad_parts += bad
    state.terminal_rows = eps.num_rows
    #: unit -> (attempt, infra kind) of its latest infrastructure-failure row
    infra: dict[str, tuple[int, str]] = {}
    #: unit -> (attempt, end reason) of its latest completing row
    final: dict[str, tuple[int, str]] = {}
    ended: dict[str, int] = {}
    for unit_id, attempt, reason, error in zip(*(eps.column(c).to_pylist() for c in cols)):
        state._seen(unit_id, attempt)
        ended[unit_id] = max(ended.get(unit_id, 0), attempt)
        kind = infra_failure(reason, error)
        if reason == "budget_exhausted":
            state.budget_stopped.add(unit_id)
        elif kind is not None:
            if attempt >= infra.get(unit_id, (0, ""))[0]:
                infra[unit_id] = (attempt, kind)
        else:
            state.completed.add(unit_id)
            if attempt >= final.get(unit_id, (0, ""))[0]:
                final[unit_id] = (attempt, reason or "")
    state.errored = {u: r for u, (_, r) in final.items() if r in ERROR_END_REASONS}
    if state.retry == "errors":
        state.completed -= set(state.errored)
    # an infrastructure failure after the latest completing row (a --retry errors attempt) counts
    state.infra_failed = {u: k for u, (a, k) in infra.items() if u not in state.completed and a > final.get(u, (0, ""))[0]}
    state.budget_stopped -= state.completed
    state.budget_stopped -= set(state.infra_failed)
    return ended


def _read_failure_events(store: RunStore, state: RunState, ended: dict[str, int]) -> None:
    """Failed attempts (events) after each unit's last terminal row count toward its attempts."""
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
        # a unit that ended (e.g. gave up after its workers died) starts a fresh count when retried
        if kind in FAILED_ATTEMPT_EVENTS and (unit_id not in ended or attempt > ended[unit_id]):
            state.failures[unit_id] = state.failures.get(unit_id, 0) + 1


def _read_attempt_ids(store: RunStore, state: RunState) -> None:
    """Every attempt number used so far (rows of the other tables, the ledger journal): a new
    attempt never reuses one."""
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


def journal_episode_ids(store: RunStore) -> set[str]:
    """Episode ids named by the call keys (``<episode_id>#<call>``) of the ledger journal."""
    return entries.episode_ids(store.read_bytes(JOURNAL_FILE))


def run_spend(store: RunStore) -> entries.JournalSpend | None:
    """What the run spent by the gateway's ledger journal (None: no journal, e.g. a backend
    without the gateway): the figure ``recap status``, the end-of-run lines and the stop line
    print, the same the ledger counts against the caps (:func:`workers.gateway.entries.journal_spend`)."""
    data = store.read_bytes(JOURNAL_FILE)
    return entries.journal_spend(data) if data else None


def attempt_spend(store: RunStore, episode_id: str) -> AttemptSpend:
    """The spend of ``episode_id`` by the gateway's ledger journal
    (:func:`workers.gateway.entries.attempt_spend`). For the row of a unit the driver gave up
    on: its worker died with the counts, the journal kept them."""
    return entries.attempt_spend(store.read_bytes(JOURNAL_FILE), episode_id)


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


# --------------------------------------------------------------------------------------------
# the gateway's budget journal: find a torn or corrupt line, and repair a torn last one
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class JournalIssue:
    """A line of the ledger journal that is not a complete entry.

    ``torn``: the last line (a crash mid-write; the entry never completed, so its call was
    never sent or its settlement stays open and is charged at its reserved worst case) - safe
    to cut away. Otherwise a line in the middle is corrupt: the spend cannot be restored
    without guessing, so nothing cuts it automatically."""

    path: str
    line: int
    lines: int
    torn: bool
    good_end: int
    size: int

    def describe(self) -> str:
        if self.torn:
            return (
                f"ledger journal {self.path}: line {self.line} of {self.lines} is torn (a crash mid-write); "
                f"the next resume drops it, keeping a backup (or now: recap resume <run> --repair)"
            )
        return (
            f"ledger journal {self.path}: line {self.line} of {self.lines} is corrupt and not the last line; "
            f"the run's spend cannot be restored from it - restore the file from a backup "
            f"(recap resume --repair only cuts a torn last line)"
        )


def scan_journal(data: bytes, path: str = JOURNAL_FILE) -> JournalIssue | None:
    """The first line of a journal's bytes that is not a complete entry (its line number as an
    editor shows it), or None (:func:`workers.gateway.journal.scan`, where the format lives)."""
    bad = scan(data)
    return None if bad is None else JournalIssue(path, bad.line, bad.lines, bad.torn, bad.good_end, bad.size)


def journal_issue(store: RunStore) -> JournalIssue | None:
    """What is wrong with the run folder's ledger journal (None: nothing, or no journal)."""
    data = store.read_bytes(JOURNAL_FILE)
    if not data:
        return None
    where = f"{store.location.rstrip('/')}/{JOURNAL_FILE}"
    return scan_journal(data, where)


def check_journal(store: RunStore, provider_models: Mapping[str, str] | None = None) -> None:
    """Refuse (one line, before anything starts) a journal corrupt before its last line; a
    torn last line is left to the ledger, which cuts it when it opens the journal. With the
    sweep's ``provider_models`` (model name -> model string), also a journal written before
    spend was kept by model name whose model strings this sweep's entries share
    (:func:`workers.gateway.entries.check_keys`)."""
    issue = journal_issue(store)
    if issue is not None and not issue.torn:
        raise RunFolderError(issue.describe())
    if provider_models is not None:
        where = f"ledger journal {store.location.rstrip('/')}/{JOURNAL_FILE}"
        try:
            entries.check_keys(store.read_bytes(JOURNAL_FILE), provider_models, where)
        except LedgerKeyError as exc:
            raise RunFolderError(str(exc)) from None


def repair_run(store: RunStore) -> str:
    """``recap resume RUN --repair``: cut a torn last line off the ledger journal, keeping a
    backup of the whole file next to it; refuse a corrupt line in the middle (and a folder a
    live driver or ledger holds). Returns one line saying what was done."""
    store.require_identity()
    store.check_unlocked()
    issue = journal_issue(store)
    if issue is None:
        return f"nothing to repair in {store.location}: the ledger journal is intact"
    if not issue.torn:
        raise RunFolderError(
            issue.describe().replace(
                "(recap resume --repair only cuts a torn last line)",
                "- --repair only cuts a torn last line, so it changed nothing",
            )
        )
    stamp = time.strftime("%Y%m%dT%H%M%S", time.gmtime())
    if store.remote:
        data = store.read_bytes(JOURNAL_FILE) or b""
        backup_name = f"{JOURNAL_FILE}.bak-{stamp}"
        store.write_bytes(backup_name, data)
        store.write_bytes(JOURNAL_FILE, data[: issue.good_end])
        backup = f"{store.location.rstrip('/')}/{backup_name}"
    else:
        path = store.path / JOURNAL_FILE
        with open(path, "r+b") as fh:
            try:  # no live ledger may hold it (the gateway's own lock)
                fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                raise RunFolderError(
                    f"{path} is held by a live ledger (a driver is running on this run); repair it once that driver has ended"
                ) from None
            data = fh.read()
            again = scan_journal(data, str(path))
            if again is None or not again.torn:  # changed under us
                raise RunFolderError(f"{path} changed while it was being repaired; run recap status {store.location}")
            backup_path = path.with_name(f"{path.name}.bak-{stamp}")
            n = 1
            while backup_path.exists():
                n += 1
                backup_path = path.with_name(f"{path.name}.bak-{stamp}-{n}")
            shutil.copy2(path, backup_path)
            with open(backup_path, "rb") as b:
                os.fsync(b.fileno())
            fh.truncate(again.good_end)
            fh.flush()
            os.fsync(fh.fileno())
            issue = again
        backup = str(backup_path)
    cut = issue.size - issue.good_end
    return (
        f"repaired {issue.path}: cut the torn last line {issue.line} ({cut} bytes); "
        f"the whole file before the repair is kept as {backup}"
    )
