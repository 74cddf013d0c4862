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
import time
import uuid
from dataclasses import replace
from typing import Any, Literal

from pipeline.attempts import Hooks
from pipeline.backend import ModelBackend
from pipeline.cap_policy import CapPolicy
from pipeline.errors import PipelineError, RunFolderError
from pipeline.events import EventBuffer
from pipeline.mirror import mirror_dir, pull
from pipeline.prepare import Prepared

# prepare, RunSummary and the exit codes: the CLI, tests and benches import them from here
from pipeline.prepare import prepare as prepare
from pipeline.raysetup import init_ray, needs_metrics, shutdown_ray
from pipeline.resume import (
    RETRY_MODES,
    Retry,
    RunState,
    load_state,
)
from pipeline.run_services import RunServices
from pipeline.run_summary import EXIT_INFRA as EXIT_INFRA
from pipeline.run_summary import EXIT_INTERRUPTED as EXIT_INTERRUPTED
from pipeline.run_summary import EXIT_WORK_REMAINS as EXIT_WORK_REMAINS
from pipeline.run_summary import RunSummary
from pipeline.serving.checks import check_cluster
from pipeline.serving.cost import ServeCost
from pipeline.serving.service import ServedModels
from pipeline.session import SessionLoop
from pipeline.sink_channel import SinkChannel
from pipeline.stopping import DEFAULT_GRACE_S, StopRequests
from pipeline.store import PLAN_FILE, SPEC_FILE, RunIdentity, RunStore
from pipeline.worker_pool import InProcessWorkerPool, RayWorkerPool, WorkerPool, episodes_per_process
from schemas.parts import RUN_FILE
from schemas.records import EpisodeRecord
from workers.envs.fever.pages import seal_run_folder
from workers.envs.registry import get_benchmark
from workers.episode_worker import EpisodeRunner, worker_actor
from workers.sandbox.base import NODE_RESOURCE
from workers.sink import recover_wal

#: where attempts run: Ray actors (the default), or threads of the driver (``recap run --executor in-process``)
Executor = Literal["ray", "in-process"]
EXECUTORS: tuple[Executor, ...] = ("ray", "in-process")


class Driver(SessionLoop):
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
        self.services: RunServices | None = None
        #: the models the sweep serves itself (models[].serve) and what they cost (pipeline.serving)
        self.serving: ServedModels | None = None
        self.serve_cost: ServeCost | None = None
        #: the cluster's sandbox slots (ray.sandboxes_per_node on a coding sweep); None: unbounded
        self.sandbox_slots: int | None = None
        #: the resources each episode worker asks for (the sandbox slot of a bounded coding sweep)
        self.worker_resources: dict[str, float] | None = None
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

    def _seal_wiki_pages(self, store: RunStore, ident: RunIdentity) -> None:
        """With every row written: the manifest of the Wikipedia pages the run recorded, its digest
        in run.json, which a ``snapshot:`` source of this folder must match (issue 35 item 10,
        workers/envs/fever/manifest.py). A table that cannot be read seals nothing (the digest is
        cleared, so the folder is refused as a snapshot rather than served unchecked)."""
        try:
            digest = seal_run_folder(store.path)
        except Exception:
            digest = None
        if digest != ident.wiki_manifest_sha256:
            store.write_text(RUN_FILE, replace(ident, wiki_manifest_sha256=digest).to_json() + "\n")

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
        # the run-wide actors the benchmarks declare (FEVER: one Wikipedia limit for every worker; the
        # in-process threads share their process's): on the driver's node, named in the workers' environment
        self.services = RunServices.start(self.spec, self.run_id, ray.get_runtime_context().get_node_id())
        worker_cls = worker_actor(
            num_cpus=self.spec.ray.worker_cpus,
            spread=multi_node,
            runtime_env=self.services.worker_runtime_env(),
            resources=self.worker_resources,
        )
        # a sandboxed worker holds its node's sandbox slot: one episode per process there
        asked = 1 if self.worker_resources else self.spec.ray.episodes_per_process
        per_process = episodes_per_process(self.spec.workers, ray.cluster_resources().get("CPU", 1), asked)
        return RayWorkerPool(worker_cls, self.run_id, self.channel.actor, factory, session=self.session, per_process=per_process)

    def _sandbox_resources(self) -> dict[str, float] | None:
        """``{recap_sandbox: 1}`` per episode worker when the sweep bounds sandboxes per node and
        runs a sandboxed benchmark; the cluster's total then caps the workers (``sandbox_slots``).
        PipelineError (one line) when no node declares the resource (no worker could start)."""
        import ray  # lazy: importing this module (prepare, the CLI's checks) must not load Ray

        per_node = self.spec.ray.sandboxes_per_node
        if per_node is None or not any(get_benchmark(e.benchmark).sandboxed for e in self.spec.environments):
            return None
        total = int(ray.cluster_resources().get(NODE_RESOURCE, 0))
        if total < 1:
            raise PipelineError(
                f"ray.sandboxes_per_node is {per_node} but no node of the cluster declares the resource {NODE_RESOURCE} "
                f"(start its nodes with --resources '{{\"{NODE_RESOURCE}\": {per_node}}}', or leave the setting out)"
            )
        self.sandbox_slots = total
        return {NODE_RESOURCE: 1}

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
        started_ray = init_ray(spec.ray, self.address, run=self.p.store.location, metrics=needs_metrics(spec))
        self.stop.install()  # ray.init set a SIGTERM handler of its own
        self.channel = SinkChannel(store.path, self.run_id, self.events, session=self.session)
        try:
            # a cluster that cannot host the sweep's worker actors is refused before any actor starts
            if self.executor == "ray":
                self.worker_resources = self._sandbox_resources()
            # a cluster without the GPUs/CPUs of the served models' replicas: refused before anything starts
            self.serving = ServedModels(spec, self.run_id, self._event)
            if self.serving.plans:
                check_cluster(spec, ray.cluster_resources(), spec.workers)
            node_id = ray.get_runtime_context().get_node_id()
            self.channel.start(node_id)
            if recovered is not None and recovered.rows:
                self._event("sink_log_recovered", severity="warning", rows=recovered.rows)
            # served models: deployed and ready before the gateway is pointed at them
            self.serving.start()
            if self.serving.served:
                self.backend.serve_at(self.serving.deployment_updates())  # type: ignore[attr-defined]
            self.backend.start(run_dir=str(store.path), run_id=self.run_id, runtime_env=None, node_id=node_id)
            self.backend.set_run_cap(spec.run_cap_usd)
            if self.serving.served:
                budget = self.backend.budget  # type: ignore[attr-defined]
                self.serve_cost = ServeCost(self.run_id, self.serving.served, budget, self._event, self.caps.stop_run)
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
                self._seal_wiki_pages(store, ident)
            try:
                self.backend.close()
            except Exception:
                pass
            if self.pool is not None:
                self.pool.shutdown()
            if self.services is not None:
                self.services.close()
            if self.serving is not None:
                self.serving.close()  # already down after a clean end; here after a failure
            self.channel.kill()
            if started_ray:
                shutdown_ray()
            try:
                self._push()  # whatever reached the mirror, also after a failure
            except Exception:
                pass
