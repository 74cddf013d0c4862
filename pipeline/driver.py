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
from dataclasses import dataclass
from importlib import metadata
from typing import Any

from pipeline.backend import ModelBackend, Spend
from pipeline.errors import PipelineError
from pipeline.preflight import preflight
from pipeline.progress import ProgressView, Snapshot
from pipeline.raysetup import PROJECT_ROOT, init_ray
from pipeline.resume import Pending, RunState, UnitQueue, load_state
from pipeline.spec import SweepSpec, text_hash
from pipeline.store import PLAN_FILE, SPEC_FILE, RunIdentity, RunStore
from pipeline.summary import TEST_DOUBLE_LABEL
from pipeline.units import Plan, PlanDiff, Unit, diff_plans, expand
from schemas.records import EpisodeRecord, EventRecord, RunRecord

_EPS = 1e-12


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
    ident = store.check_can_hold(spec.run)
    if ident is not None:
        store.check_unlocked()
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
    dirty = subprocess.run(["git", "status", "--porcelain"], cwd=PROJECT_ROOT, capture_output=True, text=True, timeout=10)
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

    @property
    def all_done(self) -> bool:
        return self.completed_before + self.finished_now >= self.total

    def exit_code(self) -> int:
        if self.interrupted:
            return 130
        return 0 if self.all_done else 3


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


class Driver:
    """One session of a run: start/resume, dispatch units, write terminal rows, stop on caps."""

    def __init__(self, prepared: Prepared, backend: ModelBackend, *, command: str = "", progress: str = "auto",
                 hooks: Hooks | None = None, address: str | None = None) -> None:
        self.p = prepared
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

    # -- helpers --------------------------------------------------------------------------------
    def _event(self, kind: str, *, severity: str = "info", unit: Unit | None = None, episode_id: str | None = None,
               **detail: Any) -> None:
        self._events.append(EventRecord(ts=time.time(), source="driver", kind=kind, severity=severity,
                                        episode_id=episode_id, unit_id=unit.unit_id if unit else None,
                                        detail=json.dumps(detail, sort_keys=True, default=str)))

    def _ship_events(self) -> None:
        if self._events:
            events, self._events = self._events, []
            self.sink.add_records.remote(events)

    def _new_slot(self) -> _Slot:
        self._worker_seq += 1
        wid = f"{self.session}-w{self._worker_seq:03d}"
        actor = self.worker_cls.remote(wid, self.run_id, self.sink, self.factory)
        return _Slot(wid, actor)

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
            self._stop_run(f"run cap ${cap:.2f} reached (spent ${spend.total_usd:.4f})")
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
        res = (out or {}).get("result") or {}
        env = (out or {}).get("env") or {}
        now = time.time()
        return EpisodeRecord(
            episode_id=f"{unit.unit_id}-{attempt}", unit_id=unit.unit_id, attempt=attempt,
            benchmark=env.get("benchmark") or unit.benchmark, split=env.get("split") or "", task=env.get("task") or "",
            instance_id=unit.instance_id, seed=unit.seed, method=unit.method_label, method_config=unit.method_config,
            model=unit.model_label, end_reason=end_reason or res["end_reason"], success=bool(res.get("success", False)),
            steps=int(res.get("steps", 0)), llm_calls=int(res.get("llm_calls", 0)),
            prompt_tokens=int(res.get("prompt_tokens", 0)), cached_prompt_tokens=int(res.get("cached_prompt_tokens", 0)),
            completion_tokens=int(res.get("completion_tokens", 0)), cost_usd=float(res.get("cost_usd", 0.0)),
            wall_s=float((out or {}).get("wall_s", now - started if started else 0.0)),
            step_cap=int(env.get("max_steps") or 0), step_multiplier=unit.step_multiplier,
            optimal_steps=env.get("optimal_steps"), max_depth=int(res.get("max_depth", 0)),
            error=error if error is not None else res.get("error"), worker_id=(out or {}).get("worker_id") or worker_id,
            started_at=float((out or {}).get("started_at", started)), ended_at=float((out or {}).get("ended_at", now)),
            test_double=bool((out or {}).get("test_double", unit.model.startswith("offline/"))),
        )

    def _failed_attempt(self, fl: _InFlight, kind: str, error: str, out: dict[str, Any] | None = None,
                        source: str = "worker") -> None:
        unit, attempt = fl.pending.unit, fl.pending.attempt
        self.failures[unit.unit_id] = self.failures.get(unit.unit_id, 0) + 1
        n = self.failures[unit.unit_id]
        self._event(kind, severity="warning", unit=unit, episode_id=f"{unit.unit_id}-{attempt}", attempt=attempt,
                    worker_id=fl.slot.worker_id, error=error[:1000], failures=n, max_attempts=self.spec.max_attempts)
        if n < self.spec.max_attempts:
            self.queue.retry(unit)
            return
        reason = "llm_error" if source == "client" else "env_error"
        msg = f"gave up after {n} failed attempts; last: {error}"[:2000]
        self.records_out.append(self._episode_record(unit, attempt, out, end_reason=reason, error=msg,
                                                     worker_id=fl.slot.worker_id, started=fl.started))
        self._event("unit_abandoned", severity="error", unit=unit, attempt=attempt, failures=n)
        self.summary.abandoned += 1
        self.summary.finished_now += 1

    def _finish(self, ref: Any) -> None:
        import ray
        from ray.exceptions import ActorDiedError, ActorUnavailableError, RayActorError, RayTaskError, WorkerCrashedError

        fl = self.inflight.pop(ref)
        unit, attempt = fl.pending.unit, fl.pending.attempt
        try:
            out = ray.get(ref)
        except (RayActorError, ActorDiedError, ActorUnavailableError, WorkerCrashedError) as exc:
            # the worker process is gone: replace it, retry the unit under a new attempt number
            self.summary.worker_restarts += 1
            self._event("worker_restarted", severity="warning", old_worker=fl.slot.worker_id)
            self._failed_attempt(fl, "worker_lost", f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}")
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
        else:
            self.summary.finished_now += 1
            self.summary.success_now += int(rec.success)
            self.done_times.append(time.monotonic())

    # -- dispatch ---------------------------------------------------------------------------------
    def _dispatch(self) -> None:
        while self.idle:
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
            return self._run_locked()
        finally:
            self.p.store.release_lock()

    def _run_locked(self) -> RunSummary:
        import ray

        from workers.episode_worker import worker_actor
        from workers.sink import sink_actor

        spec = self.spec
        t_start = time.monotonic()
        self.work = self._working_store()
        store = self.work
        ident = self._write_identity()
        self._push()
        self.run_id = ident.run_id
        state: RunState = load_state(store)
        started_ray = init_ray(spec.ray, self.address)
        try:
            node_id = ray.get_runtime_context().get_node_id()
            from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

            here = NodeAffinitySchedulingStrategy(node_id=node_id, soft=False)
            self.sink = sink_actor().options(scheduling_strategy=here).remote(str(store.path), self.run_id)
            self.backend.start(run_dir=str(store.path), run_id=self.run_id, runtime_env=None, node_id=node_id)
            self.backend.set_run_cap(spec.run_cap_usd)
            self.factory = self.backend.factory()
            multi_node = len([n for n in ray.nodes() if n.get("Alive")]) > 1
            self.worker_cls = worker_actor(num_cpus=spec.ray.worker_cpus, spread=multi_node)
            return self._session(state, ident, t_start)
        finally:
            if self._events or self.records_out:  # a failure: keep what is known
                try:
                    self.sink.add_records.remote(self._events + self.records_out)
                    self._events, self.records_out = [], []
                except Exception:
                    pass
            try:
                ray.get(self.sink.flush.remote(), timeout=60)
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
        self.queue = UnitQueue(plan.units, state)
        self.failures = {k: v for k, v in state.failures.items() if k in plan_ids}
        self.records_out: list[EpisodeRecord] = []
        self.done_times: list[float] = []
        self.t0 = time.monotonic()
        resumed = self.p.identity is not None
        self.sink.add_records.remote([RunRecord(
            started_at=time.time(), spec_yaml=self.p.spec_text, spec_hash=text_hash(self.p.spec_text),
            package_versions=_versions(), git_revision=_git_revision(), host=socket.gethostname(), command=self.command)])
        self._event("run_resumed" if resumed else "run_started", units=len(plan.units), completed=completed_before,
                    pending=len(self.queue), run_cap_usd=spec.run_cap_usd, workers=spec.workers)
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
                        self.sink.add_records.remote(recs, flush=terminal)
                    now = time.monotonic()
                    if ready or now - last_tick >= 0.5:
                        last_tick = now
                        spend = self.backend.spend()
                        self._check_caps(spend)
                        self._ship_events()
                        self.sink.maybe_flush.remote()
                        view.update(self._snapshot(spend))
                        self._push(force=False)
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
        self.summary.not_started = len(self.queue) + (len(self.inflight) if interrupted else 0)
        self.summary.stopped = self.run_stopped or (", ".join(sorted(self.stopped_models)) + " capped" if self.stopped_models else None)
        if self.records_out:
            self.sink.add_records.remote(self.records_out)
            self.records_out = []
        self.summary.spend_usd = spend.total_usd
        self.summary.wall_s = time.monotonic() - t_start
        self._event("run_finished" if not interrupted else "run_stopped", finished=self.summary.finished_now,
                    not_started=self.summary.not_started, spend_usd=spend.total_usd, stopped=self.summary.stopped)
        self._ship_events()
        try:
            self.backend.flush()
        finally:
            ray.get(self.sink.flush.remote())
        self._push()
        return self.summary

    def _success_before(self, plan_ids: set[str]) -> int:
        eps, _ = self.work.read_table("episodes", ["unit_id", "attempt", "success", "end_reason"])
        latest: dict[str, tuple[int, bool]] = {}
        for uid, att, ok, reason in zip(*(eps.column(c).to_pylist() for c in ("unit_id", "attempt", "success", "end_reason"))):
            if uid in plan_ids and reason != "budget_exhausted" and att >= latest.get(uid, (0, False))[0]:
                latest[uid] = (att, ok)
        return sum(1 for _, ok in latest.values() if ok)

