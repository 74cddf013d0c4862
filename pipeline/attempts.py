"""What the driver does with each attempt that comes back: its terminal row, a retry under the next attempt number, or a replaced worker.

:class:`AttemptHandling` is the part of :class:`pipeline.driver.Driver` that reads a returned
attempt (the rules for infrastructure failures and give-ups are in the driver's docstring); the
session loop (:mod:`pipeline.session`) calls :meth:`AttemptHandling._finish` for each.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

from pipeline.backend import ModelBackend
from pipeline.cap_policy import CapPolicy
from pipeline.episode_rows import episode_record
from pipeline.errors import PipelineError
from pipeline.events import EventBuffer
from pipeline.leftovers import Leftovers
from pipeline.resume import INFRA_ERROR, AttemptSpend, UnitQueue, attempt_spend, infra_failure
from pipeline.run_summary import RunSummary
from pipeline.sink_channel import SinkChannel, SinkLost
from pipeline.spec import SweepSpec
from pipeline.store import RunStore
from pipeline.units import Unit
from pipeline.worker_pool import Finished, WorkerPool
from schemas.kinds import EventKind, RowEndReason, Severity
from schemas.outcomes import EpisodeOutcome
from schemas.records import EpisodeRecord


@dataclass
class Hooks:
    """Test and tooling hooks (all optional): ``on_dispatch(unit, attempt, worker handle)`` and
    ``on_result(unit, attempt, outcome)``."""

    on_dispatch: Callable[[Unit, int, Any], None] | None = None
    on_result: Callable[[Unit, int, EpisodeOutcome], None] | None = None


class AttemptHandling:
    """The driver's handling of returned attempts, over the session state the driver sets up
    (declared here; :class:`pipeline.driver.Driver` assigns it)."""

    spec: SweepSpec
    backend: ModelBackend
    hooks: Hooks
    events: EventBuffer
    caps: CapPolicy
    pool: WorkerPool | None
    channel: SinkChannel | None
    work: RunStore
    records_out: list[EpisodeRecord]
    #: unit -> what its last failed attempt was lost to ("worker_lost", "client", "agent")
    last_failure: dict[str, str]
    failures: dict[str, int]
    n_workers: int
    summary: RunSummary
    queue: UnitQueue
    done_times: list[float]
    #: removes what lost workers' environments left running (pipeline.leftovers)
    leftovers: Leftovers
    #: the cluster's sandbox slots, which cap the workers (None: no bound)
    sandbox_slots: int | None

    # -- helpers --------------------------------------------------------------------------------
    def _event(
        self,
        kind: EventKind,
        *,
        severity: Severity = "info",
        unit: Unit | None = None,
        episode_id: str | None = None,
        **detail: Any,
    ) -> None:
        self.events.add(kind, severity=severity, unit_id=unit.unit_id if unit else None, episode_id=episode_id, **detail)

    def _send(self, records: list[Any], *, flush: bool = False) -> None:
        assert self.channel is not None
        self.channel.send(records, flush=flush)

    def _ship_events(self) -> None:
        if self.events:
            self._send(list(self.events.drain()))

    def _is_test_double(self, label: str) -> bool:
        try:
            return self.spec.model(label).test_double
        except KeyError:
            return False

    # -- attempts -------------------------------------------------------------------------------
    def _journal_spend(self, episode_id: str) -> AttemptSpend:
        """An attempt's calls, tokens and cost by the ledger journal (its worker is gone)."""
        return attempt_spend(self.work, episode_id)

    def _infra_failed(self, unit: Unit, attempt: int, kind: str) -> None:
        """A unit ended in an infrastructure failure: not done, retried by the next resume."""
        self.summary.infra_failed += 1
        self.summary.infra_kinds[kind] = self.summary.infra_kinds.get(kind, 0) + 1
        self._event(
            "unit_failed",
            severity="error",
            unit=unit,
            episode_id=f"{unit.unit_id}-{attempt}",
            attempt=attempt,
            failure=kind,
            retry="recap resume",
        )

    def _failed_attempt(
        self,
        fin: Finished,
        kind: Literal["attempt_failed", "worker_lost"],
        error: str,
        out: EpisodeOutcome | None = None,
        source: str = "worker",
    ) -> None:
        """An attempt without an ending: retried under the next attempt number, or, its
        attempts used up, given up on with a terminal row saying why."""
        unit, attempt = fin.pending.unit, fin.pending.attempt
        self.failures[unit.unit_id] = self.failures.get(unit.unit_id, 0) + 1
        self.last_failure[unit.unit_id] = "worker_lost" if kind == "worker_lost" else source
        n = self.failures[unit.unit_id]
        self._event(
            kind,
            severity="warning",
            unit=unit,
            episode_id=f"{unit.unit_id}-{attempt}",
            attempt=attempt,
            worker_id=fin.slot.worker_id,
            error=error[:1000],
            failures=n,
            max_attempts=self.spec.max_attempts,
        )
        if n < self.spec.max_attempts:
            self.queue.retry(unit)
            return
        lost_to = self.last_failure[unit.unit_id]
        infra = lost_to if lost_to in ("worker_lost", "client") else None
        # an agent that crashed on every attempt is an outcome (env_error); a lost worker or a
        # failing model client is infrastructure (infra_error, retried by recap resume)
        reason: RowEndReason = INFRA_ERROR if infra else ("llm_error" if source == "client" else "env_error")
        marker = f" (infrastructure: {infra})" if infra else ""
        msg = f"gave up after {n} failed attempts{marker}; last: {error}"[:2000]
        rec = episode_record(
            unit,
            attempt,
            out,
            end_reason=reason,
            error=msg,
            worker_id=fin.slot.worker_id,
            started=fin.started,
            journal_spend=self._journal_spend,
        )
        self.records_out.append(rec)
        self._event("unit_abandoned", severity="error", unit=unit, attempt=attempt, failures=n)
        self.summary.abandoned += 1
        # the rule resume and status apply to the row (a last error naming a dead actor is
        # worker_lost too): what they will retry, this session counts as failed (exit 4)
        failed = infra or infra_failure(rec.end_reason, rec.error)
        if failed:
            self._infra_failed(unit, attempt, failed)
        else:
            self.summary.finished_now += 1

    def _finish(self, key: Any) -> None:
        """One attempt came back: its terminal row, a retry, or a worker replaced."""
        assert self.pool is not None and self.channel is not None
        fin = self.pool.collect(key)
        unit, attempt = fin.pending.unit, fin.pending.attempt
        if fin.failure == "elsewhere":
            # the worker lives; its task failed on another actor: the sink, when it is gone
            why = self.channel.gone()
            if why is not None:
                self.pool.restore(fin)  # not finished: a resume runs it again
                raise SinkLost(why)
            self._failed_attempt(fin, "attempt_failed", fin.error)
            self.pool.release(fin)
            return
        if fin.failure == "worker_lost":
            # the worker process is gone: replace it, retry the unit under a new attempt number
            self.summary.worker_restarts += 1
            self._event("worker_restarted", severity="warning", old_worker=fin.slot.worker_id)
            self._failed_attempt(fin, "worker_lost", fin.error)
            self.leftovers.remove(fin.slot.worker_id)  # its sandboxes: the worker never closed them
            if self.summary.worker_restarts > max(10, 3 * self.n_workers):
                raise PipelineError(f"episode workers keep dying ({self.summary.worker_restarts} restarts); last: {fin.error}")
            self.pool.add_worker()
            return
        if fin.failure == "task_raised":
            self._failed_attempt(fin, "attempt_failed", fin.error)
            return
        out = fin.outcome
        assert out is not None
        if self.hooks.on_result:
            self.hooks.on_result(unit, attempt, out)
        if out.crash is not None:
            self._failed_attempt(fin, "attempt_failed", f"{out.crash.source}: {out.crash.error}", out, source=out.crash.source)
            return
        rec = episode_record(unit, attempt, out, journal_spend=self._journal_spend)
        self.records_out.append(rec)
        if rec.end_reason == "budget_exhausted":
            self.summary.budget_stopped += 1
            refusal = out.result.refusal if out.result is not None else None
            self.caps.on_refusal(unit.model_label, refusal, rec.error, self.backend.spend())
            return
        kind = infra_failure(rec.end_reason, rec.error)
        if kind is not None:
            self._infra_failed(unit, attempt, kind)
            return
        self.summary.finished_now += 1
        self.summary.success_now += int(rec.success)
        self.done_times.append(time.monotonic())
