"""One driver session's loop: start units while workers are idle, collect what returns, stop on caps, signals and a lost sink.

:class:`SessionLoop` is the part of :class:`pipeline.driver.Driver` that runs between starting
the workers and closing the sink; what a signal does is in :mod:`pipeline.stopping`.
"""

from __future__ import annotations

import socket
import time
from typing import Any

from pipeline.attempts import AttemptHandling
from pipeline.backend import Spend
from pipeline.errors import PipelineError
from pipeline.leftovers import Leftovers
from pipeline.mirror import PUSH_EVERY_S, push
from pipeline.prepare import Prepared
from pipeline.progress import ProgressView, Snapshot
from pipeline.provenance import git_revision, package_versions
from pipeline.resume import RunState, UnitQueue, is_final
from pipeline.run_summary import RunSummary
from pipeline.serving.cost import ServeCost
from pipeline.serving.service import ServedModels
from pipeline.sink_channel import SinkLost
from pipeline.spec import text_hash
from pipeline.stopping import StopRequests
from pipeline.store import RunIdentity
from pipeline.summary import TEST_DOUBLE_LABEL
from pipeline.units import order_units
from recap.plural import count
from schemas.records import EpisodeRecord, RunRecord


class SessionLoop(AttemptHandling):
    """The session loop over the state :class:`pipeline.driver.Driver` sets up."""

    p: Prepared
    command: str
    progress_mode: str
    stop: StopRequests
    stop_grace_s: float
    _last_push: float
    serving: ServedModels | None
    serve_cost: ServeCost | None

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

    def _push(self, force: bool = True) -> None:
        if not self.p.store.remote:
            return
        now = time.monotonic()
        if force or now - self._last_push >= PUSH_EVERY_S:
            self._last_push = now
            push(self.work.path, self.p.store.location)

    def _session(self, state: RunState, ident: RunIdentity, t_start: float) -> RunSummary:
        """Start what is left, run it to the end (or to a stop), then write what is known."""
        plan_ids = self._begin(state, ident)
        self._announce(state, plan_ids)
        # what an earlier session of this run left running (a driver killed with SIGKILL)
        self.leftovers = Leftovers(self.spec, ident.run_id, self._event)
        self.leftovers.remove()
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
        if self.sandbox_slots is not None:  # no more workers than the nodes have sandbox slots
            self.n_workers = min(self.n_workers, self.sandbox_slots)
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
        serve_cost = getattr(self, "serve_cost", None)
        if serve_cost is not None:
            serve_cost.tick()  # the served models' replica time, charged as it accrues
        self.spend_seen = self.backend.spend()
        self.caps.check(self.spend_seen)
        self._ship_events()
        self.channel.maybe_flush()
        view.update(self._snapshot(self.spend_seen))
        self._push(force=False)

    def _close_session(self, t_start: float) -> RunSummary:
        """The session's counts, its last rows and events, the gateway's flush; a lost sink is an error."""
        assert self.pool is not None and self.channel is not None
        self._stop_serving()  # before the spend is read: its last replica time is part of it
        stop, spend = self.stop, self.spend_seen
        lost = self.channel.lost
        self.leftovers.remove()  # what the episodes cut by a stop (their workers killed) left
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
                f"{count(self.summary.finished_now, 'episode')} finished this session {'is' if self.summary.finished_now == 1 else 'are'} written, "
                f"{count(self.summary.not_started, 'unit')} {'was' if self.summary.not_started == 1 else 'were'} not finished; continue with: recap resume {self.p.store.location}"
            )
        return self.summary

    def _stop_serving(self) -> None:
        """No episode is running: the served models go down and their last replica time is charged
        (before the ledger closes), with the spend the session reports."""
        serving, serve_cost = getattr(self, "serving", None), getattr(self, "serve_cost", None)
        if serving is not None:
            serving.close()
        if serve_cost is not None:
            serve_cost.close()
            self.spend_seen = self.backend.spend()

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
                f"recap: stopping: no new units; waiting up to {self.stop_grace_s:g}s for the {count(running, 'episode')} in flight "
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
            f"recap: stopping now: {count(running, 'episode')} in flight {'is' if running == 1 else 'are'} cut"
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
