"""The models a sweep serves itself, as a run service: deployed before the first unit, taken down at the end.

Why a run service: a served model belongs to the run like its gateway does - started by the
session that needs it, named to the gateway as an OpenAI-compatible ``api_base``, taken down
when the session ends however it ends. Ray Serve runs it: one Serve application per served
model, named ``recap-<run id>-<index>`` and routed at ``/recap/<run id>/<index>``, so that two
runs on one cluster never share a replica and a session can find what an earlier session of
its run left.

* start: Serve is started on the cluster when it is not running (HTTP on the loopback of the
  driver's node, a free port) - and then shut down at the end -, else the running one is
  used and only this run's applications are removed. Each application is ready when Serve
  reports all its replicas running (a replica runs once its health check passed: Serve calls
  each replica's ``check_health``) and the route answers ``GET .../v1/models``; not ready
  within ``ready_timeout_s``, or failed: one line, the session stops before any unit.
* the gateway: ``api_base`` = the route, ``max_concurrency`` = replicas x max_in_flight, the
  in-flight limit adapting between ``replicas`` and that to the calls' latency against their
  no-queue baseline, to the replicas' waiting requests (read about once a second while calls
  are in flight: :func:`queue_source`, :mod:`workers.gateway.queue_feed`) and to capacity
  errors (:mod:`workers.gateway.adaptive`; each change an ``events`` row of kind
  ``concurrency_limit``) (:meth:`ServedModels.deployment_updates`).
* a replica that dies mid-run: Serve starts another; the calls it held fail with a 5xx and the
  gateway retries them (``server_error``), so an episode never sees the loss.
* stop: :meth:`ServedModels.close` (the session's end, Ctrl-C: the driver's ``finally``).
  A driver killed with SIGKILL: on a local cluster the cluster's watcher takes Serve down with
  everything else (:mod:`pipeline.local_cluster`); on a cluster joined with ``--address`` the
  applications outlive it, and the next session of the run (``recap resume``) removes them
  before deploying its own (:meth:`ServedModels.remove_leftovers`: the run folder's lock says no
  live driver owns them).
"""

from __future__ import annotations

import logging
import socket
import time
import urllib.request
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from pipeline.errors import PipelineError
from pipeline.serving.engines import ServePlan, application, serve_plan
from pipeline.spec import SweepSpec
from workers.gateway.queue_feed import SGLANG_WAITING, VLLM_WAITING
from workers.llm.providers import QueueSource

log = logging.getLogger(__name__)

HOST = "127.0.0.1"
#: seconds between two looks at a deploying application
POLL_S = 0.5


def app_prefix(run_id: str) -> str:
    """The name prefix of every Serve application of run ``run_id``."""
    return f"recap-{run_id}-"


@dataclass
class Served:
    """One served model once deployed."""

    plan: ServePlan
    app: str
    route: str
    api_base: str
    #: time.time() when its replicas were asked for (what the cost counts from)
    started_at: float
    ready_s: float = 0.0


def queue_source(plan: ServePlan, app: str) -> QueueSource:
    """Where the gateway reads the waiting requests of ``plan``'s replicas (Serve application
    ``app``), per engine (why each: :mod:`workers.serving.queue_source`): the test double answers
    vLLM's gauge from each replica; llama.cpp's server exposes no metrics, so Serve's count of
    each replica's requests less the one it runs; vLLM / SGLang under ``ray.serve.llm`` through
    Ray's metrics agents, the samples labelled with the served model."""
    if plan.engine == "test-double":
        return QueueSource(kind="replica_metrics", app=app, gauges=VLLM_WAITING)
    if plan.engine == "llama.cpp":
        return QueueSource(kind="replica_ongoing", app=app, running=1)
    gauges = SGLANG_WAITING if plan.engine == "sglang" else VLLM_WAITING
    return QueueSource(kind="ray_metrics", app=app, gauges=gauges, labels={"model_name": plan.served_name})


def _free_port() -> int:
    with socket.socket() as s:
        s.bind((HOST, 0))
        return int(s.getsockname()[1])


def serve_running() -> bool:
    """Whether a Serve controller runs on the connected cluster."""
    import ray  # lazy: Ray loads only where a session uses it
    from ray.serve._private.constants import SERVE_CONTROLLER_NAME, SERVE_NAMESPACE

    try:
        ray.get_actor(SERVE_CONTROLLER_NAME, namespace=SERVE_NAMESPACE)
        return True
    except ValueError:
        return False


def _http_port() -> int:
    """The HTTP port of the running Serve's proxies."""
    import ray  # lazy: as above
    from ray.serve._private.constants import SERVE_CONTROLLER_NAME, SERVE_NAMESPACE

    controller: Any = ray.get_actor(SERVE_CONTROLLER_NAME, namespace=SERVE_NAMESPACE)
    config: Any = ray.get(controller.get_http_config.remote())
    return int(config.port)


def serve_apps() -> dict[str, Any]:
    """Application name -> its status on the connected cluster (empty when Serve is not running)."""
    from ray import serve  # lazy: Serve loads only where a sweep serves a model

    if not serve_running():
        return {}
    return dict(serve.status().applications)


@dataclass
class ServedModels:
    """The run's served models (none when no model entry has ``serve``)."""

    spec: SweepSpec
    run_id: str
    event: Callable[..., None]
    served: dict[str, Served] = field(default_factory=dict)
    #: whether this session started Serve on the cluster (then it shuts it down)
    started_serve: bool = False
    closed: bool = False

    @property
    def plans(self) -> list[ServePlan]:
        return [serve_plan(m) for m in self.spec.models if m.serve is not None]

    def remove_leftovers(self) -> int:
        """Remove what an earlier session of this run left deployed (a killed driver on a joined
        cluster); how many applications went."""
        from ray import serve  # lazy: as above

        mine = [name for name in serve_apps() if name.startswith(app_prefix(self.run_id))]
        for name in mine:
            serve.delete(name)
            self.event("serve_leftover_removed", severity="warning", app=name)
        return len(mine)

    def start(self) -> None:
        """Deploy every served model and wait until each is ready (PipelineError otherwise: what
        was deployed is taken down again)."""
        plans = self.plans
        if not plans:
            return
        from ray import serve  # lazy: as above

        self.remove_leftovers()
        if not serve_running():
            serve.start(http_options={"host": HOST, "port": _free_port()})
            self.started_serve = True
        port = _http_port()
        try:
            for index, plan in enumerate(plans):
                app = f"{app_prefix(self.run_id)}{index}"
                route = f"/recap/{self.run_id}/{index}"
                t0 = time.time()
                serve.run_many(
                    [serve.api.RunTarget(target=application(plan, "server"), name=app, route_prefix=route)],
                    wait_for_ingress_deployment_creation=False,
                    wait_for_applications_running=False,
                )
                self.served[plan.label] = Served(plan, app, route, f"http://{HOST}:{port}{route}/v1", t0)
            for s in self.served.values():
                self._wait_ready(s)
                s.ready_s = time.time() - s.started_at
                self.event(
                    "serve_started",
                    model=s.plan.label,
                    engine=s.plan.engine,
                    replicas=s.plan.replicas,
                    gpus_per_replica=s.plan.gpus,
                    max_in_flight=s.plan.max_in_flight,
                    app=s.app,
                    api_base=s.api_base,
                    ready_s=round(s.ready_s, 3),
                    test_double=s.plan.engine == "test-double",
                )
        except BaseException:
            self.close()
            raise

    def _wait_ready(self, s: Served) -> None:
        deadline = s.started_at + s.plan.ready_timeout_s
        while True:
            app = serve_apps().get(s.app)
            status = str(getattr(app, "status", "")) if app is not None else ""
            if status.endswith("DEPLOY_FAILED") or status.endswith("UNHEALTHY"):
                message = " ".join(str(getattr(app, "message", "") or "").split())[:300]
                raise PipelineError(f"{s.plan.label}: serving failed to start ({s.plan.engine}): {message or status}")
            if status.endswith("RUNNING") and self._all_replicas_running(app, s.plan.replicas) and self._answers(s):
                return
            if time.time() > deadline:
                raise PipelineError(
                    f"{s.plan.label}: serving was not ready within serve.ready_timeout_s={s.plan.ready_timeout_s:g}s "
                    f"(application {s.app}: {status or 'not deployed'})"
                )
            time.sleep(POLL_S)

    @staticmethod
    def _all_replicas_running(app: Any, replicas: int) -> bool:
        """Every deployment of the application has only running replicas (each passed its
        health check), and the model's own deployment has all ``replicas`` of them."""
        deployments = getattr(app, "deployments", {}) or {}
        states = [dict(d.replica_states or {}) for d in deployments.values()]
        if not states or any(set(st) - {"RUNNING"} or not st.get("RUNNING") for st in states):
            return False
        return max(int(st["RUNNING"]) for st in states) >= replicas

    @staticmethod
    def _answers(s: Served) -> bool:
        try:
            with urllib.request.urlopen(s.api_base + "/models", timeout=5) as resp:
                return bool(resp.status == 200)
        except OSError:
            return False

    def deployment_updates(self) -> dict[str, dict[str, Any]]:
        """Model name -> the gateway deployment's fields the service sets: the route as
        ``api_base``, every replica's share of calls as ``max_concurrency``, one call per
        replica as ``min_concurrency`` (the in-flight limit adapts between them to the replicas'
        latency, queue and lost replicas: workers.gateway.adaptive), and where the replicas'
        waiting requests are read (``queue_source``: :func:`queue_source`)."""
        return {
            label: {
                "api_base": s.api_base,
                "max_concurrency": s.plan.concurrency,
                "min_concurrency": s.plan.replicas,
                "queue_source": queue_source(s.plan, s.app),
            }
            for label, s in self.served.items()
        }

    def close(self) -> None:
        """Take this run's applications down (and Serve, when this session started it)."""
        if self.closed or (not self.served and not self.started_serve):
            return
        self.closed = True
        from ray import serve  # lazy: as above

        for s in self.served.values():
            try:
                serve.delete(s.app)
            except Exception as exc:  # the cluster went away: nothing left to delete there
                log.warning("could not delete the Serve application %s: %s", s.app, exc)
            self.event("serve_stopped", model=s.plan.label, app=s.app, held_s=round(time.time() - s.started_at, 3))
        if self.started_serve:
            try:
                if not serve_apps():
                    serve.shutdown()
            except Exception as exc:
                log.warning("could not shut Serve down: %s", exc)
