"""The driver: runs a sweep's units on Ray and writes one terminal row per attempt.

Shape of a run::

    driver ──(unit, attempt)──> EpisodeWorker x N ──rows──> Sink ──> RUN_DIR/<table>/part-*.parquet
       │                             │ LLMRequest
       │                             └──────────> model backend (LLM gateway actors) ──> llm_calls
       └── terminal episodes rows, events ──> Sink

Why the driver writes the ``episodes`` rows: it is the only party that knows an attempt ended
(the worker returned) or failed (the worker died). A worker killed mid-episode leaves at most
orphan messages/steps under its attempt's ``episode_id``; the unit is retried under the next
attempt number, and an ``events`` row records the loss. A unit whose attempts all fail gets one
terminal row saying so, so a broken unit cannot stall a run forever.

Caps: the model backend refuses calls that would pass a cap (episodes then end with
``budget_exhausted``); the driver stops *starting* episodes of a model (or all of them) once its
spend reaches its cap or an episode was refused for lack of budget.

Infrastructure failures: a unit whose episode ended because the model service failed
(connection, auth, rate limit, timeout, server error, not found - see
:func:`pipeline.resume.infra_failure`), or that the driver gave up on after its workers died,
gets its terminal row like any other - end reason ``infra_error``, its split, task and the
spend the ledger journal recorded for the attempt - but does not count as done: ``recap resume`` (or ``recap
run`` of the same sweep, say with the ``api_base`` fixed) runs it again under the next attempt
number. Such a failure ends the unit for this session (the gateway already retried transient
errors); the session's exit status says so.

The sink: a restartable actor that logs every batch before acknowledging it (see
:mod:`workers.sink`), so a killed sink comes back without losing a row and the senders' calls
are retried on it. Should it stay dead (its restarts used up), the driver stops at once: it
writes the rows the dead sink had logged and the terminal rows it holds itself, and exits with
an error naming ``recap resume``, which re-runs only what was never written. A task failure
caused by the sink is never counted as a worker death.

Exit status of ``run``/``resume`` (:meth:`RunSummary.exit_code`; the CLI adds 2 for bad
input, a folder in use or a sink that stayed dead):

* 0 - every unit of the plan is done;
* 3 - work remains: a cap stopped the session (or units were not started);
* 4 - at least one unit ended this session in an infrastructure failure (``EXIT_INFRA``): fix
  the cause and retry those units with ``recap resume RUN``;
* 130 - interrupted (Ctrl-C / SIGTERM) with work left: the first signal stops starting units and
  lets the episodes in flight finish (up to ``stop_grace_s``), the second cuts them
  (:mod:`pipeline.stopping`); either way what was paid for is written and ``recap resume``
  continues.

Ray: a local cluster this driver starts is shut down at the end of the session; should the
driver be killed, the cluster's watcher stops it, or else the next ``recap run``/``recap resume``
does (:mod:`pipeline.local_cluster`).
"""

from __future__ import annotations

import shutil
import socket
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

from pipeline.backend import ModelBackend, Spend
from pipeline.cap_policy import CapPolicy
from pipeline.episode_rows import episode_record
from pipeline.errors import PipelineError, RunFolderError
from pipeline.events import EventBuffer
from pipeline.mirror import PUSH_EVERY_S, mirror_dir, pull, push
from pipeline.prepare import Prepared

# prepare, RunSummary and the exit codes: the CLI, tests and benches import them from here
from pipeline.prepare import prepare as prepare
from pipeline.progress import ProgressView, Snapshot
from pipeline.provenance import git_revision, package_versions
from pipeline.raysetup import init_ray, shutdown_ray
from pipeline.resume import (
    INFRA_ERROR,
    RETRY_MODES,
    AttemptSpend,
    Retry,
    RunState,
    UnitQueue,
    attempt_spend,
    infra_failure,
    is_final,
    load_state,
)
from pipeline.run_summary import EXIT_INFRA as EXIT_INFRA
from pipeline.run_summary import EXIT_INTERRUPTED as EXIT_INTERRUPTED
from pipeline.run_summary import EXIT_WORK_REMAINS as EXIT_WORK_REMAINS
from pipeline.run_summary import RunSummary
from pipeline.sink_channel import SinkChannel, SinkLost
from pipeline.spec import text_hash
from pipeline.stopping import DEFAULT_GRACE_S, StopRequests
from pipeline.store import PLAN_FILE, SPEC_FILE, RunIdentity, RunStore
from pipeline.summary import TEST_DOUBLE_LABEL
from pipeline.units import Unit, order_units
from pipeline.worker_pool import Finished, InProcessWorkerPool, RayWorkerPool, WorkerPool
from schemas.kinds import EventKind, RowEndReason, Severity
from schemas.outcomes import EpisodeOutcome
from schemas.records import EpisodeRecord, RunRecord
from workers.episode_worker import EpisodeRunner, worker_actor
from workers.sink import recover_wal


@dataclass
class Hooks:
    """Test and tooling hooks (all optional): ``on_dispatch(unit, attempt, worker handle)`` and
    ``on_result(unit, attempt, outcome)``."""

    on_dispatch: Callable[[Unit, int, Any], None] | None = None
    on_result: Callable[[Unit, int, EpisodeOutcome], None] | None = None


#: where attempts run: Ray actors (the default), or threads of the driver (``recap run --executor in-process``)
Executor = Literal["ray", "in-process"]
EXECUTORS: tuple[Executor, ...] = ("ray", "in-process")


class Driver:
    """One session of a run: lock the folder, start what is left, turn each returned attempt
    into its terminal row or a retry, stop on caps, signals and a lost sink.

    The roles it composes, each tested alone: :class:`pipeline.worker_pool.WorkerPool` (where
    attempts run), :class:`pipeline.cap_policy.CapPolicy` (what no longer starts),
    :class:`pipeline.sink_channel.SinkChannel` (rows to the sink, or to the folder when it is
    lost), :func:`pipeline.episode_rows.episode_record` (the terminal row) and
    :class:`pipeline.events.EventBuffer`."""

    def __init__(
        self,
        prepared: Prepared,
        backend: ModelBackend,
        *,
        command: str = "",
        progress: str = "auto",
        hooks: Hooks | None = None,
        address: str | None = None,
        retry: Retry = "infra",
        executor: Executor = "ray",
        stop_grace_s: float = DEFAULT_GRACE_S,
    ) -> None:
        if retry not in RETRY_MODES:
            raise PipelineError(f"--retry must be one of {', '.join(RETRY_MODES)}, got {retry!r}")
        if executor not in EXECUTORS:
            raise PipelineError(f"--executor must be one of {', '.join(EXECUTORS)}, got {executor!r}")
        self.p = prepared
        #: what this session re-runs besides unfinished units (see :func:`pipeline.resume.load_state`)
        self.retry: Retry = retry
        self.executor: Executor = executor
        self.spec = prepared.spec
        self.backend = backend
        self.command = command
        self.progress_mode = progress
        self.hooks = hooks or Hooks()
        self.address = address
        #: distinguishes worker ids of successive sessions of one run
        self.session = uuid.uuid4().hex[:4]
        self.events = EventBuffer()
        self.caps = CapPolicy(self.spec, self.events.add)
        self.pool: WorkerPool | None = None
        self.channel: SinkChannel | None = None
        self._last_push = time.monotonic()
        self.work: RunStore = prepared.store
        self.records_out: list[EpisodeRecord] = []
        #: unit -> what its last failed attempt was lost to ("worker_lost", "client", "agent")
        self.last_failure: dict[str, str] = {}
        self.failures: dict[str, int] = {}
        self.run_id = ""
        self.n_workers = 0
        #: SIGINT/SIGTERM during the session (pipeline.stopping): the first stops gracefully
        self.stop = StopRequests()
        #: seconds a graceful stop waits for the episodes in flight before cutting them
        self.stop_grace_s = stop_grace_s

    @property
    def sink(self) -> Any:
        """The sink actor (None before the session starts it)."""
        return self.channel.actor if self.channel is not None else None

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

    # -- dispatch ---------------------------------------------------------------------------------
    def _dispatch(self) -> None:
        assert self.pool is not None and self.channel is not None
        while self.pool.has_idle() and self.channel.lost is None:
            p = self.queue.take(lambda u: self.caps.allows(u.model_label))
            if p is None:
                return
            slot = self.pool.submit(p)
            if self.hooks.on_dispatch:
                self.hooks.on_dispatch(p.unit, p.attempt, slot.handle)

    def _snapshot(self, spend: Spend) -> Snapshot:
        done = self.summary.completed_before + self.summary.finished_now
        running = self.pool.in_flight() if self.pool is not None else 0
        eta = None
        if self.done_times:
            elapsed = time.monotonic() - self.t0
            rate = len(self.done_times) / max(elapsed, 1e-6)
            remaining = len(self.queue) + running
            eta = remaining / rate if rate > 0 else None
        try:
            rates = {
                label + (TEST_DOUBLE_LABEL if self._is_test_double(label) else ""): r
                for label, r in self.backend.rate_stats().items()
            }
        except Exception:
            rates = {}
        return Snapshot(
            total=self.summary.total,
            done=done,
            success=self.success_before + self.summary.success_now,
            running=running,
            spend_usd=spend.total_usd,
            run_cap_usd=self.spec.run_cap_usd,
            eta_s=eta,
            rates=rates,
            restarts=self.summary.worker_restarts,
            stopped=self.caps.stopped,
        )

    # -- the run folder ---------------------------------------------------------------------------
    def _write_identity(self) -> RunIdentity:
        store = self.work
        ident = self.p.identity or store.create_identity(self.spec.run)
        store.write_text(SPEC_FILE, self.p.spec_text if self.p.spec_text.endswith("\n") else self.p.spec_text + "\n")
        store.write_text(PLAN_FILE, self.p.plan.to_json() + "\n")
        return ident

    def _working_store(self) -> RunStore:
        """The run folder itself, or for an object-store URI its local mirror (pulled first)."""
        if not self.p.store.remote:
            return self.p.store
        local = mirror_dir(self.p.store.location)
        if self.p.identity is None and local.exists():
            shutil.rmtree(local)  # a stale mirror of an earlier run at the same URI
        local.mkdir(parents=True, exist_ok=True)
        if self.p.identity is not None:
            pull(self.p.store.location, local)
        return RunStore(local)

    def _push(self, force: bool = True) -> None:
        if not self.p.store.remote:
            return
        now = time.monotonic()
        if force or now - self._last_push >= PUSH_EVERY_S:
            self._last_push = now
            push(self.work.path, self.p.store.location)

    # -- the session ------------------------------------------------------------------------------
    def run(self) -> RunSummary:
        """One session: lock the folder, run what is left, write the terminal rows, unlock."""
        self.p.store.acquire_lock()
        self.stop.install()
        try:
            self._recheck_folder()
            return self._run_locked()
        finally:
            self.stop.restore()
            self.p.store.release_lock()

    def _recheck_folder(self) -> None:
        """With the lock held: the folder is still what :func:`prepare` saw (another driver may
        have started - and ended - a run there in between)."""
        now = self.p.store.check_can_hold(self.spec.run)
        before = self.p.identity
        if (now is None) != (before is None) or (now is not None and before is not None and now.run_id != before.run_id):
            raise RunFolderError(
                f"run folder {self.p.store.location} changed while this driver was starting "
                "(another driver ran there); run the command again"
            )

    def _make_pool(self, factory: Any) -> WorkerPool:
        import ray  # lazy: importing this module (prepare, the CLI's checks) must not load Ray

        assert self.channel is not None
        if self.executor == "in-process":
            sink = self.channel.actor
            return InProcessWorkerPool(
                lambda wid: EpisodeRunner(
                    wid, self.run_id, factory, send=lambda rows: sink.add.remote(rows), wait=lambda ref: ray.get(ref)
                ),
                session=self.session,
            )
        multi_node = len([n for n in ray.nodes() if n.get("Alive")]) > 1
        worker_cls = worker_actor(num_cpus=self.spec.ray.worker_cpus, spread=multi_node)
        return RayWorkerPool(worker_cls, self.run_id, self.channel.actor, factory, session=self.session)

    def _run_locked(self) -> RunSummary:
        import ray  # lazy: importing this module (prepare, the CLI's checks) must not load Ray

        spec = self.spec
        t_start = time.monotonic()
        self.work = self._working_store()
        store = self.work
        ident = self._write_identity()
        self._push()
        self.run_id = ident.run_id
        # rows a sink had acknowledged when the last session died with it (a driver kill)
        recovered = recover_wal(store.path) if self.p.identity is not None else None
        state: RunState = load_state(store, retry=self.retry)
        started_ray = init_ray(spec.ray, self.address, run=self.p.store.location)
        self.stop.install()  # ray.init set a SIGTERM handler of its own
        self.channel = SinkChannel(store.path, self.run_id, self.events, session=self.session)
        try:
            node_id = ray.get_runtime_context().get_node_id()
            self.channel.start(node_id)
            if recovered is not None and recovered.rows:
                self._event("sink_log_recovered", severity="warning", rows=recovered.rows)
            self.backend.start(run_dir=str(store.path), run_id=self.run_id, runtime_env=None, node_id=node_id)
            self.backend.set_run_cap(spec.run_cap_usd)
            self.pool = self._make_pool(self.backend.factory())
            summary = self._session(state, ident, t_start)
            summary.recovered_rows = recovered.rows if recovered is not None else 0
            return summary
        finally:
            if self.channel.actor is not None:
                if self.events or self.records_out:  # a failure: keep what is known
                    recs = [*self.events.drain(), *self.records_out]
                    self.records_out = []
                    try:
                        self._send(recs, flush=True)
                    except Exception:
                        pass
                try:
                    self.channel.close()
                except Exception:
                    pass
            try:
                self.backend.close()
            except Exception:
                pass
            if self.pool is not None:
                self.pool.shutdown()
            self.channel.kill()
            if started_ray:
                shutdown_ray()
            try:
                self._push()  # whatever reached the mirror, also after a failure
            except Exception:
                pass

    def _session(self, state: RunState, ident: RunIdentity, t_start: float) -> RunSummary:
        """Start what is left, run it to the end (or to a stop), then write what is known."""
        plan_ids = self._begin(state, ident)
        self._announce(state, plan_ids)
        self._start_workers()
        self._drive()
        return self._close_session(t_start)

    def _begin(self, state: RunState, ident: RunIdentity) -> set[str]:
        """This session's summary, queue and counters from the run's state; the plan's unit ids."""
        spec, plan = self.spec, self.p.plan
        plan_ids = {u.unit_id for u in plan.units}
        self.summary = RunSummary(
            location=self.p.store.location,
            run=spec.run,
            run_id=ident.run_id,
            total=len(plan.units),
            completed_before=len(state.completed & plan_ids),
        )
        self.success_before = self._success_before(plan_ids)
        # the start order (spec.order): interleaved over arms by default, so a cap that binds
        # early leaves a balanced subsample; the same spec gives the same order on every resume
        self.queue = UnitQueue(order_units(plan.units, spec), state)
        self.failures = {k: v for k, v in state.failures.items() if k in plan_ids}
        self.records_out = []
        self.done_times: list[float] = []
        self.t0 = time.monotonic()
        #: the backend's spend as last seen (what the session reports, also after a Ctrl-C)
        self.spend_seen = Spend()
        return plan_ids

    def _announce(self, state: RunState, plan_ids: set[str]) -> None:
        """The run row (spec, versions, revision, host, command) and the started/resumed event."""
        spec, plan = self.spec, self.p.plan
        resumed = self.p.identity is not None
        self._send(
            [
                RunRecord(
                    started_at=time.time(),
                    spec_yaml=self.p.spec_text,
                    spec_hash=text_hash(self.p.spec_text),
                    package_versions=package_versions(),
                    git_revision=git_revision(),
                    host=socket.gethostname(),
                    command=self.command,
                )
            ]
        )
        retrying = {u: k for u, k in state.infra_failed.items() if u in plan_ids}
        # --retry errors: units whose latest completing row ended env_error / llm_error run again
        self.retrying_errors = {
            u: r for u, r in state.errored.items() if u in plan_ids and u not in state.completed and u not in retrying
        }
        self.summary.retried_errors = len(self.retrying_errors)
        extra: dict[str, Any] = {}
        if retrying:
            extra["retrying_failed"] = len(retrying)
        if self.retrying_errors:
            extra["retrying_errors"] = len(self.retrying_errors)
        self._event(
            "run_resumed" if resumed else "run_started",
            units=len(plan.units),
            completed=self.summary.completed_before,
            pending=len(self.queue),
            run_cap_usd=spec.run_cap_usd,
            workers=spec.workers,
            order=spec.order,
            **extra,
        )

    def _start_workers(self) -> None:
        """As many episode workers as the sweep asks for and the queue can use."""
        assert self.pool is not None
        self.caps.check(self.backend.spend())
        self.n_workers = max(1, min(self.spec.workers, len(self.queue))) if len(self.queue) else 0
        nodes = self.pool.start(self.n_workers)
        self._event("workers_started", workers=nodes, nodes=len(set(nodes.values())))

    def _drive(self) -> None:
        """The session's loop under its progress view, and what a stop, a lost sink or a third
        signal leaves to do."""
        assert self.pool is not None and self.channel is not None
        title = f"recap run {self.spec.run} -> {self.p.store.location}"
        try:
            with ProgressView(self.progress_mode, title=title) as view:
                self.stop.arm()  # from here a signal stops the session gracefully (pipeline.stopping)
                cut_reason: str | None = None
                try:
                    cut_reason = self._loop(view)
                except SinkLost as exc:
                    # stop at once: what finished is written (by the driver itself), the rest waits
                    # for a resume; the attempts in flight were cut, not failed
                    self._finish_ready_before_stop()
                    self.channel.on_lost(str(exc))
                if cut_reason is not None:
                    self._cut_now(cut_reason, view)
                self.spend_seen = self.backend.spend()
                self.caps.check(self.spend_seen)
                view.update(self._snapshot(self.spend_seen), force=True)
        except KeyboardInterrupt:
            # a third signal: stop where we are (what is written stays; the finishing below still runs)
            self.stop.count = max(self.stop.count, 2)
            self._event("interrupted", severity="warning", mode="raised", running=self.pool.in_flight(), pending=len(self.queue))
            self.pool.shutdown()

    def _loop(self, view: ProgressView) -> str | None:
        """Start units while workers are idle and collect what returns, until nothing is in
        flight; after a stop, wait for the episodes in flight. The reason they were cut, if so."""
        assert self.pool is not None
        stop = self.stop
        last_tick = 0.0
        stop_since: float | None = None
        while True:
            if stop.graceful and stop_since is None:
                stop_since = time.monotonic()
                self._stop_requested(view)
            if stop_since is None:
                self._dispatch()
            elif self.pool.in_flight() and (stop.now or time.monotonic() - stop_since >= self.stop_grace_s):
                return "signal" if stop.now else "grace_expired"
            if not self.pool.in_flight():
                return None
            ready = self.pool.wait(0.5)
            self._collect(ready)
            now = time.monotonic()
            if ready or now - last_tick >= 0.5:
                last_tick = now
                self._tick(view)

    def _collect(self, ready: list[Any]) -> None:
        """The attempts that returned: their rows go to the sink (terminal rows flushed at once)."""
        assert self.channel is not None
        for key in ready:
            self._finish(key)
        if self.records_out:
            recs, self.records_out = self.records_out, []
            # terminal rows are written at once: a unit whose episode finished must not
            # be re-run (and paid again) because its row was still buffered at a crash
            terminal = any(isinstance(r, EpisodeRecord) for r in recs)
            self._send(recs, flush=terminal)
        self.channel.check_acks()

    def _tick(self, view: ProgressView) -> None:
        """Twice a second: spend against the caps, events to the sink, the view, the mirror."""
        assert self.channel is not None
        self.spend_seen = self.backend.spend()
        self.caps.check(self.spend_seen)
        self._ship_events()
        self.channel.maybe_flush()
        view.update(self._snapshot(self.spend_seen))
        self._push(force=False)

    def _close_session(self, t_start: float) -> RunSummary:
        """The session's counts, its last rows and events, the gateway's flush; a lost sink is an error."""
        assert self.pool is not None and self.channel is not None
        stop, spend = self.stop, self.spend_seen
        lost = self.channel.lost
        cut = self.pool.in_flight() if (stop.graceful or lost is not None) else 0
        # a stop asked for while the last episodes finished left nothing to resume
        interrupted = stop.graceful and (len(self.queue) + cut > 0)
        self.summary.interrupted = interrupted
        self.summary.cut = cut if stop.graceful else 0
        self.summary.not_started = len(self.queue) + cut
        self.summary.stopped = self.caps.stopped
        if self.records_out:
            self._send(self.records_out, flush=True)
            self.records_out = []
        self.summary.spend_usd = spend.total_usd
        self.summary.wall_s = time.monotonic() - t_start
        infra: dict[str, Any] = {"infra_failed": self.summary.infra_failed} if self.summary.infra_failed else {}
        self._event(
            "run_finished" if not (interrupted or lost) else "run_stopped",
            finished=self.summary.finished_now,
            not_started=self.summary.not_started,
            spend_usd=spend.total_usd,
            stopped=self.summary.stopped or lost,
            **infra,
        )
        self._ship_events()
        try:
            self.backend.flush()
        finally:
            self.channel.close()
        self._push()
        if self.channel.lost is not None:
            self.channel.write_direct([])  # the last events
            raise PipelineError(
                f"the sink actor was lost ({self.channel.lost}); the session stopped: "
                f"{self.summary.finished_now} episodes finished this session are written, "
                f"{self.summary.not_started} units were not finished; continue with: recap resume {self.p.store.location}"
            )
        return self.summary

    def _stop_requested(self, view: ProgressView) -> None:
        """The first SIGINT/SIGTERM: nothing new starts; say how long the episodes in flight get."""
        assert self.pool is not None
        running = self.pool.in_flight()
        self._event(
            "interrupted",
            severity="warning",
            mode="graceful",
            running=running,
            pending=len(self.queue),
            grace_s=self.stop_grace_s,
        )
        if running:
            view.note(
                f"recap: stopping: no new units; waiting up to {self.stop_grace_s:g}s for the {running} episodes in flight "
                "to finish (Ctrl-C again to stop now)"
            )

    def _cut_now(self, reason: str, view: ProgressView) -> None:
        """A second signal, or the grace period over: the episodes in flight are cut. Their workers
        are stopped first, so no new call starts; the calls they completed are in the ledger
        journal (and reach ``llm_calls`` with the gateway's flush), one still at the provider
        stays charged at its worst case, and the resume runs those units again."""
        assert self.pool is not None
        running = self.pool.in_flight()
        self._event("interrupted", severity="warning", mode=reason, running=running, pending=len(self.queue))
        view.note(
            f"recap: stopping now: {running} episodes in flight are cut"
            + (" (the grace period is over)" if reason == "grace_expired" else "")
            + "; the calls they made stay recorded and the resume runs them again"
        )
        self.pool.shutdown()

    def _finish_ready_before_stop(self) -> None:
        """Results already returned when the sink was lost: their rows were acknowledged by
        the sink (logged), so their terminal rows are written too."""
        assert self.pool is not None
        if not self.pool.in_flight():
            return
        for key in self.pool.wait(0):
            try:
                self._finish(key)
            except SinkLost:
                pass

    def _success_before(self, plan_ids: set[str]) -> int:
        cols = ("unit_id", "attempt", "success", "end_reason", "error")
        eps, _ = self.work.read_table("episodes", list(cols))
        latest: dict[str, tuple[int, bool]] = {}
        for uid, att, ok, reason, error in zip(*(eps.column(c).to_pylist() for c in cols)):
            if uid in plan_ids and is_final(reason, error) and att >= latest.get(uid, (0, False))[0]:
                latest[uid] = (att, ok)
        return sum(1 for _, ok in latest.values() if ok)
