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
* 130 - interrupted (Ctrl-C / SIGTERM).
"""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import metadata
from typing import Any

from pipeline.backend import ModelBackend, Spend
from pipeline.errors import PipelineError, RunFolderError
from pipeline.preflight import preflight
from pipeline.progress import ProgressView, Snapshot
from pipeline.raysetup import PROJECT_ROOT, init_ray
from pipeline.resume import (INFRA_ERROR, INFRA_ERROR_KINDS, RETRY_MODES, Pending, Retry, RunState, UnitQueue, attempt_spend,
                             check_journal, infra_failure, is_final, load_state)
from pipeline.spec import SweepSpec, text_hash
from pipeline.store import PLAN_FILE, SPEC_FILE, RunIdentity, RunStore
from pipeline.summary import TEST_DOUBLE_LABEL
from pipeline.units import Plan, PlanDiff, Unit, diff_plans, expand, order_units
from schemas.labels import place_of
from schemas.records import EpisodeRecord, EventRecord, RunRecord

_EPS = 1e-12
#: exit status of a session in which a unit ended in an infrastructure failure
EXIT_INFRA = 4
#: exit status of a session that left work undone (a cap stopped it)
EXIT_WORK_REMAINS = 3
EXIT_INTERRUPTED = 130


# --------------------------------------------------------------------------------------------
# preparation: everything that can fail does so here, before any write
# --------------------------------------------------------------------------------------------
@dataclass
class Prepared:
    spec: SweepSpec
    spec_text: str
    plan: Plan
    store: RunStore
    identity: RunIdentity | None
    diff: PlanDiff | None


def prepare(spec: SweepSpec, spec_text: str, *, check_keys: bool = True) -> Prepared:
    """Expand and check a sweep: units, keys, prices, the output folder. Writes nothing."""
    plan = expand(spec)
    if check_keys:
        preflight(spec)
    store = RunStore(spec.output)
    store.check_unlocked()  # first: a driver starting in a fresh folder has only its lock there
    ident = store.check_can_hold(spec.run)
    if ident is not None:
        check_journal(store)  # a corrupt ledger journal: one line now, not a traceback later
    diff = diff_plans(store.read_json(PLAN_FILE), plan) if ident is not None else None
    return Prepared(spec, spec_text, plan, store, ident, diff)


def _versions() -> str:
    out = {"python": sys.version.split()[0]}
    for pkg in ("recap-eval", "ray", "litellm", "pyarrow", "duckdb", "pydantic", "alfworld", "textworld"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            pass
    return json.dumps(out, sort_keys=True)


def _git_revision() -> str | None:
    try:
        r = subprocess.run(["git", "rev-parse", "HEAD"], cwd=PROJECT_ROOT, capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.TimeoutExpired):
        return None
    rev = r.stdout.strip()
    if r.returncode != 0 or not rev:
        return None
    # tracked changes only: a run folder (or any output) inside the checkout is not a code change
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=PROJECT_ROOT,
                           capture_output=True, text=True, timeout=10)
    return rev + ("+dirty" if dirty.stdout.strip() else "")


# --------------------------------------------------------------------------------------------
# the outcome of one driver session
# --------------------------------------------------------------------------------------------
@dataclass
class RunSummary:
    location: str
    run: str
    run_id: str
    total: int
    completed_before: int
    finished_now: int = 0
    success_now: int = 0
    budget_stopped: int = 0
    abandoned: int = 0
    not_started: int = 0
    worker_restarts: int = 0
    spend_usd: float = 0.0
    stopped: str | None = None
    interrupted: bool = False
    wall_s: float = 0.0
    #: units that ended this session in an infrastructure failure (retryable), by failure kind
    infra_failed: int = 0
    infra_kinds: dict[str, int] = field(default_factory=dict)
    #: rows the sink had logged but not written when a session began (a crash), now written
    recovered_rows: int = 0
    #: units queued again because their latest completing row ended env_error / llm_error
    #: (``retry="errors"``, ``recap resume RUN --retry errors``)
    retried_errors: int = 0

    @property
    def all_done(self) -> bool:
        return self.completed_before + self.finished_now >= self.total

    def retry_hint(self) -> str | None:
        """One line on the units to retry, or None."""
        if not self.infra_failed:
            return None
        kinds = ", ".join(f"{k} {n}" for k, n in sorted(self.infra_kinds.items()))
        return (f"{self.infra_failed} units ended in an infrastructure failure ({kinds}); fix the cause, "
                f"then retry them with: recap resume {self.location}")

    def exit_code(self) -> int:
        if self.interrupted:
            return EXIT_INTERRUPTED
        if self.infra_failed:
            return EXIT_INFRA
        return 0 if self.all_done else EXIT_WORK_REMAINS


@dataclass
class Hooks:
    """Test and tooling hooks (all optional)."""

    on_dispatch: Callable[[Unit, int, Any], None] | None = None
    on_result: Callable[[Unit, int, dict[str, Any]], None] | None = None


@dataclass
class _Slot:
    worker_id: str
    actor: Any
    units: int = 0


@dataclass
class _InFlight:
    slot: _Slot
    pending: Pending
    started: float


class _SinkLost(Exception):
    """The sink actor is gone for good (its restarts used up) or does not answer."""


class Driver:
    """One session of a run: start/resume, dispatch units, write terminal rows, stop on caps."""

    #: how long the driver waits on the sink (a restart included) before it counts it as lost
    SINK_WAIT_S = 120.0

    def __init__(self, prepared: Prepared, backend: ModelBackend, *, command: str = "", progress: str = "auto",
                 hooks: Hooks | None = None, address: str | None = None, retry: Retry = "infra") -> None:
        if retry not in RETRY_MODES:
            raise PipelineError(f"--retry must be one of {', '.join(RETRY_MODES)}, got {retry!r}")
        self.p = prepared
        #: what this session re-runs besides unfinished units (see :func:`pipeline.resume.load_state`)
        self.retry: Retry = retry
        self.spec = prepared.spec
        self.backend = backend
        self.command = command
        self.progress_mode = progress
        self.hooks = hooks or Hooks()
        self.address = address
        #: distinguishes worker ids of successive sessions of one run
        self.session = uuid.uuid4().hex[:4]
        self.slots: list[_Slot] = []
        self.inflight: dict[Any, _InFlight] = {}
        self.stopped_models: set[str] = set()
        self.run_stopped: str | None = None
        self._worker_seq = 0
        self._events: list[EventRecord] = []
        self._last_push = time.monotonic()
        self.work: RunStore = prepared.store
        self.records_out: list[EpisodeRecord] = []
        self.sink: Any = None
        #: the sink's writer name: fixed for the session, so a restarted sink finds its log
        self.sink_writer = f"sink{uuid.uuid4().hex[:10]}"
        #: (ref, batch hash, rows) of the driver's batches the sink has not acknowledged yet
        self._unacked: list[tuple[Any, str, dict[str, list[dict[str, Any]]]]] = []
        #: why the sink is gone for good (None while it lives)
        self.sink_lost: str | None = None
        #: unit -> what its last failed attempt was lost to ("worker_lost", "client", "agent")
        self.last_failure: dict[str, str] = {}
        self.run_id = ""

    # -- helpers --------------------------------------------------------------------------------
    def _event(self, kind: str, *, severity: str = "info", unit: Unit | None = None, episode_id: str | None = None,
               **detail: Any) -> None:
        self._events.append(EventRecord(ts=time.time(), source="driver", kind=kind, severity=severity,
                                        episode_id=episode_id, unit_id=unit.unit_id if unit else None,
                                        detail=json.dumps(detail, sort_keys=True, default=str)))

    def _ship_events(self) -> None:
        if self._events:
            events, self._events = self._events, []
            self._send(events)

    # -- the sink -------------------------------------------------------------------------------
    def _send(self, records: list[Any], *, flush: bool = False) -> None:
        """Hand rows to the sink (kept until it acknowledges them); straight to the run folder
        once the sink is lost."""
        if not records:
            return
        from workers.sink import batch_hash, records_by_table

        rows = records_by_table(records, self.run_id)
        if self.sink_lost is not None or self.sink is None:
            self._write_direct([rows])
            return
        ref = self.sink.add.remote(rows, flush=flush)
        self._unacked.append((ref, batch_hash(rows), rows))

    def _check_acks(self, timeout: float | None = 0.0) -> None:
        """Drop the batches the sink acknowledged; raise :class:`_SinkLost` when one failed
        (or, with a timeout, when not all were acknowledged in time)."""
        import ray
        from ray.exceptions import RayActorError

        if not self._unacked or self.sink_lost is not None:
            return
        refs = [r for r, _, _ in self._unacked]
        ready, _ = ray.wait(refs, num_returns=len(refs), timeout=timeout)
        done = set(ready)
        keep, failed = [], None
        for item in self._unacked:
            if item[0] not in done:
                keep.append(item)
                continue
            try:
                ray.get(item[0])
            except RayActorError as exc:
                failed = failed or f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
                keep.append(item)
            except Exception as exc:  # the sink could not log or write them (a full disk ...)
                failed = failed or f"{type(exc).__name__}: {str(exc).splitlines()[-1] if str(exc) else ''}"
                keep.append(item)
        self._unacked = keep
        if failed:
            raise _SinkLost(f"the sink failed: {failed}")
        if timeout and keep:
            raise _SinkLost(f"the sink did not acknowledge {len(keep)} batches within {timeout:.0f}s")

    def _sink_gone(self) -> str | None:
        """Why the sink is gone for good, or None when it answers (after a restart if need be)."""
        import ray
        from ray.exceptions import GetTimeoutError, RayActorError

        if self.sink_lost is not None:
            return self.sink_lost
        try:
            ray.get(self.sink.ping.remote(), timeout=self.SINK_WAIT_S)
            return None
        except GetTimeoutError:
            return f"the sink did not answer within {self.SINK_WAIT_S:.0f}s"
        except RayActorError as exc:
            return f"the sink died: {type(exc).__name__}"

    def _on_sink_lost(self, why: str) -> None:
        """The sink is gone: write what its log holds and every batch of the driver it never
        took (the terminal rows above all) straight into the run folder."""
        import ray

        from workers.sink import recover_wal

        if self.sink_lost is not None:
            return
        self.sink_lost = why
        try:
            ray.kill(self.sink, no_restart=True)
        except Exception:
            pass
        time.sleep(1.0)  # its process gone before its log is read
        found = recover_wal(self.work.path, self.sink_writer)
        pending = [rows for _, h, rows in self._unacked if h not in found.hashes]
        self._unacked = []
        self._event("sink_lost", severity="error", reason=why, recovered_rows=found.rows,
                    driver_batches=len(pending))
        self._write_direct(pending)

    def _write_direct(self, batches: list[dict[str, list[dict[str, Any]]]]) -> None:
        """Rows written by the driver itself (the sink is lost), terminal rows last."""
        from schemas.parts import PartWriter

        if self._events:
            from workers.sink import records_by_table

            events, self._events = self._events, []
            batches = [records_by_table(events, self.run_id)] + list(batches)
        merged: dict[str, list[dict[str, Any]]] = {}
        for rows in batches:
            for table, r in rows.items():
                merged.setdefault(table, []).extend(r)
        if not merged:
            return
        writer = PartWriter(self.work.path, f"driver{self.session}{uuid.uuid4().hex[:6]}")
        for table in sorted(merged, key=lambda t: (t == "episodes", t)):
            writer.write_rows(table, merged[table])

    def _close_sink(self) -> None:
        """Every driver batch acknowledged, the buffers written, the sink's log removed."""
        import ray
        from ray.exceptions import GetTimeoutError, RayActorError

        if self.sink is None or self.sink_lost is not None:
            return
        try:
            self._check_acks(timeout=self.SINK_WAIT_S)
            ray.get(self.sink.close.remote(), timeout=self.SINK_WAIT_S)
        except _SinkLost as exc:
            self._on_sink_lost(str(exc))
        except (RayActorError, GetTimeoutError) as exc:
            self._on_sink_lost(f"the sink failed at the end of the session: {type(exc).__name__}")

    # -- workers --------------------------------------------------------------------------------
    def _new_slot(self) -> _Slot:
        self._worker_seq += 1
        wid = f"{self.session}-w{self._worker_seq:03d}"
        actor = self.worker_cls.remote(wid, self.run_id, self.sink, self.factory)
        return _Slot(wid, actor)

    @staticmethod
    def _worker_died(exc: BaseException, fl: _InFlight) -> bool:
        """The worker process itself is gone (not: its task failed on another actor)."""
        from ray.exceptions import RayTaskError

        if isinstance(exc, RayTaskError):  # its task raised: the worker lived to report it
            return False
        dead = getattr(exc, "actor_id", None)
        try:
            mine = fl.slot.actor._actor_id.hex()
        except Exception:
            mine = None
        return not (dead and mine and dead != mine)

    def _is_test_double(self, label: str) -> bool:
        try:
            return self.spec.model(label).test_double
        except KeyError:
            return False

    def _allowed(self, unit: Unit) -> bool:
        return self.run_stopped is None and unit.model_label not in self.stopped_models

    # -- caps -------------------------------------------------------------------------------------
    def _check_caps(self, spend: Spend) -> None:
        cap = self.spec.run_cap_usd
        if self.run_stopped is None and cap is not None and spend.total_usd >= cap - _EPS:
            self._stop_run(f"run cap ${cap:.2f} reached")  # the spend figure is the live one beside it
        for m in self.spec.models:
            if m.cap_usd is not None and m.name not in self.stopped_models and spend.by_model.get(m.name, 0.0) >= m.cap_usd - _EPS:
                self._stop_model(m.name, f"model cap ${m.cap_usd:.2f} of {m.name} reached")

    def _stop_run(self, why: str) -> None:
        if self.run_stopped is None:
            self.run_stopped = why
            self._event("run_cap_reached", severity="warning", reason=why)

    def _stop_model(self, name: str, why: str) -> None:
        if name not in self.stopped_models:
            self.stopped_models.add(name)
            self._event("model_cap_reached", severity="warning", model=name, reason=why)

    def _on_budget_exhausted(self, unit: Unit, error: str | None) -> None:
        """An episode was refused a call for lack of budget: stop starting more of what hit it
        (the gateway's refusal names the run budget or the model's)."""
        m = self.spec.model(unit.model_label)
        spend = self.backend.spend()
        run_cap = self.spec.run_cap_usd
        run_hit = (error or "").startswith("run budget") or m.cap_usd is None
        if run_hit:
            self._stop_run(f"run cap ${run_cap:.2f} reached (spent ${spend.total_usd:.4f})" if run_cap is not None
                           else f"a model call was refused for lack of budget: {error}")
        else:
            self._stop_model(m.name, f"model cap ${m.cap_usd:.2f} of {m.name} reached")

    # -- terminal rows ----------------------------------------------------------------------------
    def _episode_record(self, unit: Unit, attempt: int, out: dict[str, Any] | None, *, end_reason: str | None = None,
                        error: str | None = None, worker_id: str | None = None, started: float = 0.0) -> EpisodeRecord:
        """The terminal row of an attempt (schema version 2): the arm's method, label, profile
        and ablation apart; the place from :func:`schemas.labels.place_of` (ALFWorld one split,
        a row without an environment still has its split and task); an infrastructure failure
        ends ``infra_error`` with its kind first in the error; an attempt without a result (a
        unit given up on) gets the spend the ledger journal recorded for it."""
        res = (out or {}).get("result") or {}
        env = (out or {}).get("env") or {}
        now = time.time()
        reason = end_reason or res["end_reason"]
        if error is None:
            error = res.get("error")
            kind = res.get("error_kind")
            # the row's error names the LLM error kind first: what makes an infrastructure
            # failure recognisable (and retryable) from the table alone
            if reason == "llm_error" and kind in INFRA_ERROR_KINDS and not (error or "").startswith(f"{kind}:"):
                error = f"{kind}: {error or ''}".rstrip()
        if infra_failure(reason, error) is not None:
            reason = INFRA_ERROR
        spend = res if res else self._journal_spend(f"{unit.unit_id}-{attempt}")
        bench, split, task = place_of(unit.instance_id, env.get("split") or None, env.get("task") or None)
        return EpisodeRecord(
            episode_id=f"{unit.unit_id}-{attempt}", unit_id=unit.unit_id, attempt=attempt,
            benchmark=env.get("benchmark") or bench, split=split, task=task,
            instance_id=unit.instance_id, seed=unit.seed, method=unit.method, method_config=unit.method_config,
            model=unit.model_label, end_reason=reason, success=bool(res.get("success", False)),
            steps=int(res.get("steps", 0)), llm_calls=int(spend.get("llm_calls", 0)),
            prompt_tokens=int(spend.get("prompt_tokens", 0)), cached_prompt_tokens=int(spend.get("cached_prompt_tokens", 0)),
            completion_tokens=int(spend.get("completion_tokens", 0)), cost_usd=float(spend.get("cost_usd", 0.0)),
            wall_s=float((out or {}).get("wall_s", now - started if started else 0.0)),
            step_cap=int(env.get("max_steps") or 0), step_multiplier=unit.step_multiplier,
            optimal_steps=env.get("optimal_steps"), max_depth=int(res.get("max_depth", 0)),
            error=error, worker_id=(out or {}).get("worker_id") or worker_id,
            started_at=float((out or {}).get("started_at", started)), ended_at=float((out or {}).get("ended_at", now)),
            test_double=bool((out or {}).get("test_double", unit.model.startswith("offline/"))),
            label=unit.method_label, profile=unit.profile, ablation=unit.ablation_name, provider_model=unit.model,
        )

    def _journal_spend(self, episode_id: str) -> dict[str, Any]:
        """An attempt's calls, tokens and cost by the ledger journal (its worker is gone)."""
        try:
            s = attempt_spend(self.work, episode_id)
        except Exception:  # the row matters more than its spend
            return {}
        return {"llm_calls": s.calls, "prompt_tokens": s.prompt_tokens, "cached_prompt_tokens": s.cached_prompt_tokens,
                "completion_tokens": s.completion_tokens, "cost_usd": s.cost_usd}

    def _infra_failed(self, unit: Unit, attempt: int, kind: str) -> None:
        """A unit ended in an infrastructure failure: not done, retried by the next resume."""
        self.summary.infra_failed += 1
        self.summary.infra_kinds[kind] = self.summary.infra_kinds.get(kind, 0) + 1
        self._event("unit_failed", severity="error", unit=unit, episode_id=f"{unit.unit_id}-{attempt}",
                    attempt=attempt, failure=kind, retry="recap resume")

    def _failed_attempt(self, fl: _InFlight, kind: str, error: str, out: dict[str, Any] | None = None,
                        source: str = "worker") -> None:
        unit, attempt = fl.pending.unit, fl.pending.attempt
        self.failures[unit.unit_id] = self.failures.get(unit.unit_id, 0) + 1
        self.last_failure[unit.unit_id] = "worker_lost" if kind == "worker_lost" else source
        n = self.failures[unit.unit_id]
        self._event(kind, severity="warning", unit=unit, episode_id=f"{unit.unit_id}-{attempt}", attempt=attempt,
                    worker_id=fl.slot.worker_id, error=error[:1000], failures=n, max_attempts=self.spec.max_attempts)
        if n < self.spec.max_attempts:
            self.queue.retry(unit)
            return
        lost_to = self.last_failure[unit.unit_id]
        infra = lost_to if lost_to in ("worker_lost", "client") else None
        # an agent that crashed on every attempt is an outcome (env_error); a lost worker or a
        # failing model client is infrastructure (infra_error, retried by recap resume)
        reason = INFRA_ERROR if infra else ("llm_error" if source == "client" else "env_error")
        marker = f" (infrastructure: {infra})" if infra else ""
        msg = f"gave up after {n} failed attempts{marker}; last: {error}"[:2000]
        rec = self._episode_record(unit, attempt, out, end_reason=reason, error=msg, worker_id=fl.slot.worker_id,
                                   started=fl.started)
        self.records_out.append(rec)
        self._event("unit_abandoned", severity="error", unit=unit, attempt=attempt, failures=n)
        self.summary.abandoned += 1
        # the rule resume and status apply to the row (a last error naming a dead actor is
        # worker_lost too): what they will retry, this session counts as failed (exit 4)
        kind = infra or infra_failure(rec.end_reason, rec.error)
        if kind:
            self._infra_failed(unit, attempt, kind)
        else:
            self.summary.finished_now += 1

    def _finish(self, ref: Any) -> None:
        import ray
        from ray.exceptions import ActorDiedError, ActorUnavailableError, RayActorError, RayTaskError, WorkerCrashedError

        fl = self.inflight.pop(ref)
        unit, attempt = fl.pending.unit, fl.pending.attempt
        try:
            out = ray.get(ref)
        except (RayActorError, ActorDiedError, ActorUnavailableError, WorkerCrashedError) as exc:
            first = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
            if not self._worker_died(exc, fl):
                # the worker lives; its task failed on another actor: the sink, when it is gone
                why = self._sink_gone()
                if why is not None:
                    self.inflight[ref] = fl  # not finished: a resume runs it again
                    raise _SinkLost(why)
                self._failed_attempt(fl, "attempt_failed", first)
                self.idle.append(fl.slot)
                return
            # the worker process is gone: replace it, retry the unit under a new attempt number
            self.summary.worker_restarts += 1
            self._event("worker_restarted", severity="warning", old_worker=fl.slot.worker_id)
            self._failed_attempt(fl, "worker_lost", first)
            try:
                ray.kill(fl.slot.actor)
            except Exception:
                pass
            self.slots.remove(fl.slot)
            if self.summary.worker_restarts > max(10, 3 * self.n_workers):
                raise PipelineError(f"episode workers keep dying ({self.summary.worker_restarts} restarts); last: {exc}")
            slot = self._new_slot()
            self.slots.append(slot)
            self.idle.append(slot)
            return
        except RayTaskError as exc:
            self._failed_attempt(fl, "attempt_failed", str(exc).splitlines()[-1][:1000])
            self.idle.append(fl.slot)
            return
        fl.slot.units += 1
        self.idle.append(fl.slot)
        if self.hooks.on_result:
            self.hooks.on_result(unit, attempt, out)
        if out.get("crash"):
            crash = out["crash"]
            self._failed_attempt(fl, "attempt_failed", f"{crash['source']}: {crash['error']}", out, source=crash["source"])
            return
        rec = self._episode_record(unit, attempt, out)
        self.records_out.append(rec)
        if rec.end_reason == "budget_exhausted":
            self.summary.budget_stopped += 1
            self._on_budget_exhausted(unit, rec.error)
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
        while self.idle and self.sink_lost is None:
            p = self.queue.take(self._allowed)
            if p is None:
                return
            slot = self.idle.pop()
            ref = slot.actor.run_unit.remote(p.unit.payload(), p.attempt)
            self.inflight[ref] = _InFlight(slot, p, time.time())
            if self.hooks.on_dispatch:
                self.hooks.on_dispatch(p.unit, p.attempt, slot.actor)

    def _snapshot(self, spend: Spend) -> Snapshot:
        done = self.summary.completed_before + self.summary.finished_now
        eta = None
        if self.done_times:
            elapsed = time.monotonic() - self.t0
            rate = len(self.done_times) / max(elapsed, 1e-6)
            remaining = len(self.queue) + len(self.inflight)
            eta = remaining / rate if rate > 0 else None
        try:
            rates = {label + (TEST_DOUBLE_LABEL if self._is_test_double(label) else ""): r
                     for label, r in self.backend.rate_stats().items()}
        except Exception:
            rates = {}
        return Snapshot(total=self.summary.total, done=done, success=self.success_before + self.summary.success_now,
                        running=len(self.inflight), spend_usd=spend.total_usd, run_cap_usd=self.spec.run_cap_usd,
                        eta_s=eta, rates=rates, restarts=self.summary.worker_restarts,
                        stopped=self.run_stopped or (", ".join(sorted(self.stopped_models)) + " capped" if self.stopped_models else None))

    # -- the session ------------------------------------------------------------------------------
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
        import shutil

        from pipeline.mirror import mirror_dir, pull

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
        from pipeline.mirror import PUSH_EVERY_S, push

        now = time.monotonic()
        if force or now - self._last_push >= PUSH_EVERY_S:
            self._last_push = now
            push(self.work.path, self.p.store.location)

    def run(self) -> RunSummary:
        """One session: lock the folder, run what is left, write the terminal rows, unlock."""
        self.p.store.acquire_lock()
        try:
            self._recheck_folder()
            return self._run_locked()
        finally:
            self.p.store.release_lock()

    def _recheck_folder(self) -> None:
        """With the lock held: the folder is still what :func:`prepare` saw (another driver may
        have started - and ended - a run there in between)."""
        now = self.p.store.check_can_hold(self.spec.run)
        before = self.p.identity
        if (now is None) != (before is None) or (now is not None and before is not None and now.run_id != before.run_id):
            raise RunFolderError(f"run folder {self.p.store.location} changed while this driver was starting "
                                 "(another driver ran there); run the command again")

    def _run_locked(self) -> RunSummary:
        import ray

        from workers.episode_worker import worker_actor
        from workers.sink import recover_wal, sink_actor

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
        started_ray = init_ray(spec.ray, self.address)
        try:
            node_id = ray.get_runtime_context().get_node_id()
            from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

            here = NodeAffinitySchedulingStrategy(node_id=node_id, soft=False)
            self.sink = sink_actor().options(scheduling_strategy=here).remote(str(store.path), self.run_id,
                                                                              writer=self.sink_writer)
            if recovered is not None and recovered.rows:
                self._event("sink_log_recovered", severity="warning", rows=recovered.rows)
            self.backend.start(run_dir=str(store.path), run_id=self.run_id, runtime_env=None, node_id=node_id)
            self.backend.set_run_cap(spec.run_cap_usd)
            self.factory = self.backend.factory()
            multi_node = len([n for n in ray.nodes() if n.get("Alive")]) > 1
            self.worker_cls = worker_actor(num_cpus=spec.ray.worker_cpus, spread=multi_node)
            summary = self._session(state, ident, t_start)
            summary.recovered_rows = recovered.rows if recovered is not None else 0
            return summary
        finally:
            if self.sink is not None:
                if self._events or self.records_out:  # a failure: keep what is known
                    recs, self._events, self.records_out = self._events + self.records_out, [], []
                    try:
                        self._send(recs, flush=True)
                    except Exception:
                        pass
                try:
                    self._close_sink()
                except Exception:
                    pass
            try:
                self.backend.close()
            except Exception:
                pass
            for slot in self.slots:
                try:
                    ray.kill(slot.actor)
                except Exception:
                    pass
            if self.sink is not None:
                try:
                    ray.kill(self.sink)
                except Exception:
                    pass
            if started_ray:
                ray.shutdown()
            try:
                self._push()  # whatever reached the mirror, also after a failure
            except Exception:
                pass

    def _session(self, state: RunState, ident: RunIdentity, t_start: float) -> RunSummary:
        import ray

        spec, plan = self.spec, self.p.plan
        plan_ids = {u.unit_id for u in plan.units}
        completed_before = len(state.completed & plan_ids)
        self.summary = RunSummary(location=self.p.store.location, run=spec.run, run_id=ident.run_id,
                                  total=len(plan.units), completed_before=completed_before)
        self.success_before = self._success_before(plan_ids)
        # the start order (spec.order): interleaved over arms by default, so a cap that binds
        # early leaves a balanced subsample; the same spec gives the same order on every resume
        self.queue = UnitQueue(order_units(plan.units, spec), state)
        self.failures = {k: v for k, v in state.failures.items() if k in plan_ids}
        self.records_out: list[EpisodeRecord] = []
        self.done_times: list[float] = []
        self.t0 = time.monotonic()
        resumed = self.p.identity is not None
        self._send([RunRecord(
            started_at=time.time(), spec_yaml=self.p.spec_text, spec_hash=text_hash(self.p.spec_text),
            package_versions=_versions(), git_revision=_git_revision(), host=socket.gethostname(), command=self.command)])
        retrying = {u: k for u, k in state.infra_failed.items() if u in plan_ids}
        # --retry errors: units whose latest completing row ended env_error / llm_error run again
        self.retrying_errors = {u: r for u, r in state.errored.items()
                                if u in plan_ids and u not in state.completed and u not in retrying}
        self.summary.retried_errors = len(self.retrying_errors)
        self._event("run_resumed" if resumed else "run_started", units=len(plan.units), completed=completed_before,
                    pending=len(self.queue), run_cap_usd=spec.run_cap_usd, workers=spec.workers, order=spec.order,
                    **({"retrying_failed": len(retrying)} if retrying else {}),
                    **({"retrying_errors": len(self.retrying_errors)} if self.retrying_errors else {}))
        self._check_caps(self.backend.spend())
        self.n_workers = max(1, min(spec.workers, len(self.queue))) if len(self.queue) else 0
        self.slots = [self._new_slot() for _ in range(self.n_workers)]
        try:
            nodes = ray.get([s.actor.node.remote() for s in self.slots], timeout=300)
        except Exception as exc:
            raise PipelineError(f"episode workers failed to start: {str(exc).splitlines()[0]}") from None
        self._event("workers_started", workers={s.worker_id: n for s, n in zip(self.slots, nodes)},
                    nodes=len(set(nodes)))
        self.idle = list(self.slots)
        interrupted = False
        previous = signal.getsignal(signal.SIGTERM)

        def _term(signum: int, frame: Any) -> None:
            raise KeyboardInterrupt

        try:
            signal.signal(signal.SIGTERM, _term)
        except ValueError:  # not the main thread
            previous = None
        title = f"recap run {spec.run} -> {self.p.store.location}"
        last_tick = 0.0
        spend = Spend()
        try:
            with ProgressView(self.progress_mode, title=title) as view:
                try:
                    while True:
                        self._dispatch()
                        if not self.inflight:
                            break
                        ready, _ = ray.wait(list(self.inflight), num_returns=1, timeout=0.5)
                        if ready:
                            ready, _ = ray.wait(list(self.inflight), num_returns=len(self.inflight), timeout=0)
                        for ref in ready:
                            self._finish(ref)
                        if self.records_out:
                            recs, self.records_out = self.records_out, []
                            # terminal rows are written at once: a unit whose episode finished must not
                            # be re-run (and paid again) because its row was still buffered at a crash
                            terminal = any(isinstance(r, EpisodeRecord) for r in recs)
                            self._send(recs, flush=terminal)
                        self._check_acks()
                        now = time.monotonic()
                        if ready or now - last_tick >= 0.5:
                            last_tick = now
                            spend = self.backend.spend()
                            self._check_caps(spend)
                            self._ship_events()
                            self.sink.maybe_flush.remote()
                            view.update(self._snapshot(spend))
                            self._push(force=False)
                except _SinkLost as exc:
                    # stop at once: what finished is written (by the driver itself), the rest waits
                    # for a resume; the attempts in flight were cut, not failed
                    self._finish_ready_before_stop()
                    self._on_sink_lost(str(exc))
                spend = self.backend.spend()
                self._check_caps(spend)
                view.update(self._snapshot(spend), force=True)
        except KeyboardInterrupt:
            interrupted = True
            self._event("interrupted", severity="warning", running=len(self.inflight), pending=len(self.queue))
        finally:
            if previous is not None:
                signal.signal(signal.SIGTERM, previous)
        self.summary.interrupted = interrupted
        cut = len(self.inflight) if (interrupted or self.sink_lost is not None) else 0
        self.summary.not_started = len(self.queue) + cut
        self.summary.stopped = self.run_stopped or (", ".join(sorted(self.stopped_models)) + " capped" if self.stopped_models else None)
        if self.records_out:
            self._send(self.records_out, flush=True)
            self.records_out = []
        self.summary.spend_usd = spend.total_usd
        self.summary.wall_s = time.monotonic() - t_start
        self._event("run_finished" if not (interrupted or self.sink_lost) else "run_stopped",
                    finished=self.summary.finished_now, not_started=self.summary.not_started,
                    spend_usd=spend.total_usd, stopped=self.summary.stopped or self.sink_lost,
                    **({"infra_failed": self.summary.infra_failed} if self.summary.infra_failed else {}))
        self._ship_events()
        try:
            self.backend.flush()
        finally:
            self._close_sink()
        self._push()
        if self.sink_lost is not None:
            self._write_direct([])  # the last events
            raise PipelineError(
                f"the sink actor was lost ({self.sink_lost}); the session stopped: "
                f"{self.summary.finished_now} episodes finished this session are written, "
                f"{self.summary.not_started} units were not finished; continue with: recap resume {self.p.store.location}")
        return self.summary

    def _finish_ready_before_stop(self) -> None:
        """Results already returned when the sink was lost: their rows were acknowledged by
        the sink (logged), so their terminal rows are written too."""
        import ray

        if not self.inflight:
            return
        ready, _ = ray.wait(list(self.inflight), num_returns=len(self.inflight), timeout=0)
        for ref in ready:
            try:
                self._finish(ref)
            except _SinkLost:
                pass
        self.idle = []

    def _success_before(self, plan_ids: set[str]) -> int:
        cols = ("unit_id", "attempt", "success", "end_reason", "error")
        eps, _ = self.work.read_table("episodes", list(cols))
        latest: dict[str, tuple[int, bool]] = {}
        for uid, att, ok, reason, error in zip(*(eps.column(c).to_pylist() for c in cols)):
            if uid in plan_ids and is_final(reason, error) and att >= latest.get(uid, (0, False))[0]:
                latest[uid] = (att, ok)
        return sum(1 for _, ok in latest.values() if ok)
