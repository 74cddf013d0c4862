"""Starting (or joining) Ray for a sweep.

Why a module: every process of a run — the driver, the gateway, the episode workers, the sink —
must import litellm offline (``LITELLM_LOCAL_MODEL_COST_MAP``), find this project and the
benchmark data folders. Locally the project may not be pip-installed (a checkout), so its root
is put on the workers' ``PYTHONPATH``; on a cluster the nodes have it installed (cluster.yaml).
A local Ray listens on the loopback only (see :func:`_loopback_node`), in a Ray temp folder of
its own with an owner record (:mod:`pipeline.local_cluster`), so that the processes a killed
driver leaves behind can be found - and only those - and stopped by the next ``recap run`` or
``recap resume``; :func:`shutdown_ray` ends it and stops any straggler.
"""

from __future__ import annotations

import ipaddress
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from pipeline import local_cluster
from pipeline.spec import RaySpec
from workers.envs.data_paths import CACHE_ENV
from workers.envs.registry import data_env_vars
from workers.log_setup import LEVEL_VAR
from workers.sandbox.base import NODE_RESOURCE
from workers.worker_setup import HOOK as WORKER_SETUP_HOOK

PROJECT_ROOT = Path(__file__).resolve().parents[1]


def forwarded_vars() -> tuple[str, ...]:
    """Forwarded from the driver's environment to every Ray worker when set: each registered
    benchmark's data variables (its ``data_env_vars`` hook) and recap-eval's cache folder and the log level (:mod:`workers.log_setup`), so a
    worker finds the data by the same rule as the driver (workers/envs/data_paths.py)."""
    return (*data_env_vars(), CACHE_ENV, LEVEL_VAR)


#: glibc's malloc arenas per process. Why: a Ray actor runs its calls on several threads and glibc
#: gives each thread an arena of its own, whose freed memory stays fragmented; over a soak the
#: gateway and the episode workers grew by 2.3 and 6.2 KB a call with glibc's default (8 per
#: core), by 0.6 and 1.4 with 2 (bench/soak.py, 16 workers, one run each on a busy machine). The GIL
#: serialises Python anyway, so fewer arenas cost little. Read by glibc when the process starts: set in
#: the workers' environment, which the raylet starts them with. The driver's own value wins.
MALLOC_ARENAS_VAR = "MALLOC_ARENA_MAX"
MALLOC_ARENAS = os.environ.get(MALLOC_ARENAS_VAR) or "2"


def runtime_env() -> dict[str, Any]:
    """The Ray ``runtime_env`` for every worker: litellm offline, no usage stats, few malloc arenas,
    the data and log-level variables forwarded, the project root on PYTHONPATH, and
    :mod:`workers.worker_setup` run first in each worker process (no pyarrow, numpy or pydantic
    loaded by Ray into a process that does not use them)."""
    env_vars = {"LITELLM_LOCAL_MODEL_COST_MAP": "True", "RAY_USAGE_STATS_ENABLED": "0", MALLOC_ARENAS_VAR: MALLOC_ARENAS}
    for name in forwarded_vars():
        if os.environ.get(name):
            env_vars[name] = os.environ[name]
    path = [str(PROJECT_ROOT)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
    env_vars["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(path))
    return {"env_vars": env_vars, "worker_process_setup_hook": WORKER_SETUP_HOOK}


def actor_runtime_env(extra: dict[str, str] | None = None) -> dict[str, Any] | None:
    """The ``runtime_env`` to start a run's actors with: None when the local cluster this process
    started already gives its workers exactly :func:`runtime_env`'s variables and ``extra`` adds
    none, else :func:`runtime_env` with ``extra``.

    Why None where it can be: Ray starts a worker whose job or actor has a runtime environment
    through ``setup_worker.py`` - a second Python that imports Ray (about 1 s of CPU) and then
    execs the worker - and only a worker without one directly (the raylet drops that step for an
    empty environment: ``ray/_private/services.py``, "later erasing them if needed"). A cluster
    started here has the variables in its raylet's environment (:func:`init_ray`), which every
    worker inherits; a cluster joined with ``--address`` is somebody else's, so its workers get
    the variables the usual way. A variable changed since the start (a test pointing a data
    folder elsewhere) sends the whole environment again."""
    full = runtime_env()
    env_vars = {**full["env_vars"], **(extra or {})}
    if _started_env is not None and env_vars == _started_env:
        return None
    return {**full, "env_vars": env_vars}


def _setup_hook_var() -> dict[str, str]:
    """The variable by which Ray runs a ``worker_process_setup_hook`` in each worker it starts
    (``ray/_private/runtime_env/setup_hook.py``: a hook given as a module path is only this
    variable, read by ``default_worker.py``): set in a local cluster's raylet environment, the hook
    runs in every worker without a runtime_env."""
    try:  # lazy: Ray loads only where a session uses it
        from ray._private.ray_constants import WORKER_PROCESS_SETUP_HOOK_ENV_VAR
    except ImportError:  # another Ray layout: the hook comes with runtime_env() only
        return {}
    return {WORKER_PROCESS_SETUP_HOOK_ENV_VAR: WORKER_SETUP_HOOK}


@contextmanager
def _worker_environment(env_vars: dict[str, str]) -> Iterator[None]:
    """``env_vars`` in this process's environment while ``ray.init`` starts the local cluster's
    processes (they copy it: the raylet then starts every worker with it), restored after."""
    before = {name: os.environ.get(name) for name in env_vars}
    os.environ.update(env_vars)
    try:
        yield
    finally:
        for name, value in before.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


#: Ray's internal settings for a cluster started here (``ray.init(_system_config=...)``: Ray hands
#: them to the GCS and the raylet on their command lines, and every worker reads them from there).
#: Why: by default every task and actor call of the run (one gateway call, two budget calls and
#: a sink batch per model call) is reported by its worker once a second and kept in the GCS, up
#: to 100,000 tasks, for the dashboard's task pages and ``ray.util.state`` - which recap-eval
#: never reads: over a 12,000-call soak the GCS grew 43 -> 170 MB (bench/soak.py) and every process
#: spent CPU on the reports. ``task_events_report_interval_ms: 0`` turns the reporting off in
#: every worker; the GCS's own cap is lowered too, for anything that still reports (a driver of
#: another Ray version joining). Metrics (Prometheus figures the dashboard agent collects from
#: every process) go the same way: nobody here scrapes them. ``agent_register_timeout_ms``: how
#: long the raylet retries a request to the runtime-env agent before it exits (Ray's default 30 s
#: on Linux); with the dashboard off that agent starts on the first such request
#: (:mod:`pipeline.lazy_runtime_env_agent`), and a loaded machine must not turn its start into
#: the end of the run.
SYSTEM_CONFIG: dict[str, Any] = {
    "task_events_report_interval_ms": 0,
    "task_events_max_num_task_in_gcs": 1000,
    "task_events_max_num_profile_events_per_task": 0,
    "enable_timeline": False,
    "enable_metrics_collection": False,
    "agent_register_timeout_ms": 120_000,
}

#: the temp folder of the local cluster this process started (None: none, or joined one)
_owned: Path | None = None
#: the worker variables that cluster's raylet was started with (:func:`actor_runtime_env`)
_started_env: dict[str, str] | None = None


def init_ray(ray_spec: RaySpec, address: str | None = None, *, run: str = "", metrics: bool = False) -> bool:
    """Start a local Ray (or join ``address``). Returns True when this call started Ray (and so
    must shut it down, with :func:`shutdown_ray`); an already initialised Ray (tests share one)
    is reused as is. A local cluster gets its own temp folder, recording this process as its
    owner and ``run`` (the run folder) for the message of whoever cleans up after a crash.

    ``metrics``: a local cluster that collects metrics, with Ray's own dashboard agent (which
    exports them): a sweep serving vLLM or SGLang reads its replicas' queue from there
    (:mod:`workers.serving.queue_source`, ``ray_metrics``); without it the adaptive limit would
    have latency and errors only (:func:`needs_metrics`)."""
    global _owned, _started_env
    import ray  # lazy: Ray loads only where a session uses it

    os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    if ray.is_initialized():
        return False
    address = address or ray_spec.address
    common: dict[str, Any] = {
        "log_to_driver": False,
        "configure_logging": True,
        "logging_level": "error",
    }
    if address:  # somebody's cluster: its workers get the variables as the job's runtime_env
        if _is_loopback(address):  # a local Ray started on the loopback (ours, or ray start --node-ip-address 127.0.0.1)
            with _loopback_node():
                ray.init(address=address, runtime_env=runtime_env(), **common)
        else:
            ray.init(address=address, runtime_env=runtime_env(), **common)
    else:
        folder = local_cluster.claim(run)
        local_cluster.watch(folder)  # stops the cluster if this process dies without shutting it down
        # the workers' variables in the raylet's own environment, no job runtime_env: every worker
        # then starts without Ray's setup_worker step (actor_runtime_env)
        env_vars = runtime_env()["env_vars"]
        try:
            lean = not (ray_spec.dashboard or metrics)
            config = SYSTEM_CONFIG if not metrics else {**SYSTEM_CONFIG, "enable_metrics_collection": True}
            with _loopback_node(), _lean_head(lean), _worker_environment({**env_vars, **_setup_hook_var()}):
                ray.init(
                    num_cpus=ray_spec.num_cpus or os.cpu_count() or 2,
                    include_dashboard=ray_spec.dashboard,
                    dashboard_host="127.0.0.1",
                    object_store_memory=ray_spec.object_store_mb * 1024 * 1024,
                    resources={NODE_RESOURCE: ray_spec.sandboxes_per_node} if ray_spec.sandboxes_per_node else None,
                    _temp_dir=str(folder),
                    _system_config=config,
                    **common,
                )
        except BaseException:
            ray.shutdown()
            local_cluster.release(folder)
            raise
        _owned, _started_env = folder, dict(env_vars)
    return True


def needs_metrics(spec: Any) -> bool:
    """A sweep that serves a model whose queue figure comes from Ray's metrics (vLLM, SGLang
    under ``ray.serve.llm``): its local cluster collects metrics (:func:`init_ray`)."""
    from pipeline.serving.engines import METRICS_ENGINES

    return any(m.serve is not None and m.serve.engine in METRICS_ENGINES for m in getattr(spec, "models", []))


def shutdown_ray() -> None:
    """``ray.shutdown()``; for a local cluster this process started, also stop any of its
    processes still there and mark its owner record ended (:func:`pipeline.local_cluster.release`)."""
    global _owned, _started_env
    import ray  # lazy: Ray loads only where a session uses it

    ray.shutdown()
    folder, _owned, _started_env = _owned, None, None
    if folder is not None:
        local_cluster.release(folder)


def _is_loopback(address: str) -> bool:
    """Whether ``address`` (host:port, or ``auto`` = the latest local cluster) is on the loopback;
    a driver joining such a cluster must take the loopback as its own node address too, or
    Ray looks for a local node under the machine's outward address and waits for ever."""
    if address == "auto":
        try:
            from ray._private.services import canonicalize_bootstrap_address  # lazy: Ray loads only where a session uses it

            address = canonicalize_bootstrap_address("auto") or ""
        except Exception:
            return False
    host = address.split("://")[-1].rsplit(":", 1)[0].strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


@contextmanager
def _loopback_node() -> Iterator[None]:
    """Make a local Ray start on 127.0.0.1.

    Why: Ray takes the machine's outward-facing address as the node address and then binds
    its servers (GCS, raylet, object manager, workers, dashboard agent) on it or on 0.0.0.0,
    so a laptop or a shared box running a sweep would expose them to its network. A local
    run has no other node (clusters are joined with ``--address``), so its node address is the
    loopback, and with it every one of those servers listens on 127.0.0.1 only. Ray offers no
    public switch for this; its node-address lookup returns the loopback when "clusters" are
    disabled (the setting it uses on macOS/Windows), which is what this sets for the start."""
    try:
        from ray._private import ray_constants  # lazy: Ray loads only where a session uses it
    except ImportError:  # another Ray layout: leave the default
        yield
        return
    before = ray_constants.ENABLE_RAY_CLUSTER
    ray_constants.ENABLE_RAY_CLUSTER = False
    try:
        yield
    finally:
        ray_constants.ENABLE_RAY_CLUSTER = before


@contextmanager
def _lean_head(lean: bool) -> Iterator[None]:
    """Start a local Ray without the processes a sweep never reads, unless the sweep asks for the
    dashboard (``ray: {dashboard: true}``): no dashboard (API server) process, the dashboard
    agent replaced by :mod:`pipeline.idle_dashboard_agent`, the runtime-environment agent
    started on first use, no log monitor and no autoscaler monitor.

    Why: ``include_dashboard=False`` still starts the API server (the dashboard process with its
    usage-stats module), the dashboard agent with its HTTP server, metrics and event modules, the
    log monitor (it forwards workers' output to drivers: ours set ``log_to_driver=False``) and the
    autoscaler monitor (a local node never scales): ~240 MB PSS together, a third of a run's
    fixed memory (issue 37, item 3). ``ray start`` has switches for the monitors
    (``--no-monitor``, ``--include-log-monitor``); ``ray.init`` passes none of them, nor one to
    leave the agent out (its maintainers keep it for runtime environments and metrics,
    ray-project/ray#19420). So, for the start only, this sets the two monitor switches on the
    node's parameters, skips the API server, and has Ray choose its minimal agent - what a
    ``pip install ray`` without ``[default]`` runs - by reporting the dashboard's optional
    dependencies missing (``ray._private.utils.get_dashboard_dependency_error``, read while
    ``ray.init`` builds the agent's command line). Even that agent imports every dashboard
    module it finds and polls for the absent dashboard (~78 MB PSS): the raylet's command line
    (``ray._private.services.start_ray_process`` for the raylet) gets
    :mod:`pipeline.idle_dashboard_agent` as its dashboard agent instead (a standard-library
    process of ~5 MB that publishes the agent's ports unused and lives as long as the raylet:
    :func:`_with_lean_agents`), and Ray's runtime-environment agent (~48 MB) behind
    :mod:`pipeline.lazy_runtime_env_agent`, which holds its port and becomes Ray's agent on the
    raylet's first request: a run's actors start without a runtime_env here
    (:func:`actor_runtime_env`), some still with one (the first such start waits for the
    agent, ~2-4 s). What a sweep uses stays: the GCS, the raylet, the workers, runtime
    environments. Another Ray layout (a private name gone): the default start."""
    if not lean:
        yield
        return
    try:  # lazy: Ray loads only where a session uses it
        from ray._private import node as ray_node
        from ray._private import parameter as ray_parameter
        from ray._private import services as ray_services
        from ray._private import utils as ray_utils

        params_init = ray_parameter.RayParams.__init__
        start_api_server = ray_node.Node.start_api_server
        dependency_error = ray_utils.get_dashboard_dependency_error
        start_process = ray_services.start_ray_process
        raylet_type = ray_services.ray_constants.PROCESS_TYPE_RAYLET
    except (ImportError, AttributeError):
        yield
        return

    def lean_params(self: Any, *args: Any, **kwargs: Any) -> None:
        params_init(self, *args, **kwargs)
        self.include_log_monitor = False
        self.no_monitor = True

    def lean_agents_raylet(command: list[str], process_type: str, *args: Any, **kwargs: Any) -> Any:
        if process_type == raylet_type:
            command = _with_lean_agents(command)
        return start_process(command, process_type, *args, **kwargs)

    ray_parameter.RayParams.__init__ = lean_params  # type: ignore[method-assign]
    ray_node.Node.start_api_server = lambda self, **_: None  # type: ignore[method-assign]
    ray_utils.get_dashboard_dependency_error = lambda: ImportError("the dashboard is off (ray: {dashboard: false})")
    ray_services.start_ray_process = lean_agents_raylet
    try:
        yield
    finally:
        ray_parameter.RayParams.__init__ = params_init  # type: ignore[method-assign]
        ray_node.Node.start_api_server = start_api_server  # type: ignore[method-assign]
        ray_utils.get_dashboard_dependency_error = dependency_error
        ray_services.start_ray_process = start_process


#: the raylet's arguments holding the commands it starts its two agents with
_DASHBOARD_AGENT_ARG = "--dashboard_agent_command="
_RUNTIME_ENV_AGENT_ARG = "--runtime_env_agent_command="
#: :mod:`pipeline.idle_dashboard_agent` and :mod:`pipeline.lazy_runtime_env_agent`, each run as a
#: file (``python -I -S``: standard library only, no project import)
IDLE_AGENT = Path(__file__).resolve().with_name("idle_dashboard_agent.py")
LAZY_AGENT = Path(__file__).resolve().with_name("lazy_runtime_env_agent.py")


def _with_lean_agents(raylet_command: list[str]) -> list[str]:
    """The raylet's command line with :mod:`pipeline.idle_dashboard_agent` as its dashboard agent
    (the agent's three port files published unused, nothing else) and
    :mod:`pipeline.lazy_runtime_env_agent` in front of Ray's runtime-env agent (started on the
    raylet's first request). The port files are named by Ray's own rule from the node id and
    session folder on Ray's agent command lines. An agent whose command line is not as expected
    (another Ray layout, a quoting this module would not give back unchanged) keeps Ray's."""
    import shlex
    import subprocess

    try:  # lazy: Ray loads only where a session uses it
        from ray._raylet import (  # type: ignore[attr-defined]  # Ray's compiled module: no stubs for it
            DASHBOARD_AGENT_LISTEN_PORT_NAME,
            METRICS_AGENT_PORT_NAME,
            METRICS_EXPORT_PORT_NAME,
            RUNTIME_ENV_AGENT_PORT_NAME,
            get_port_filename,
        )
    except ImportError:
        return raylet_command

    def rewrite(command: list[str], prefix: str, lean: Any) -> list[str]:
        at = [i for i, arg in enumerate(command) if arg.startswith(prefix)]
        if len(at) != 1:
            return command
        text = command[at[0]][len(prefix) :]
        agent = shlex.split(text)
        if subprocess.list2cmdline(agent) != text:  # not read back as the raylet would run it
            return command
        opts = dict(arg[2:].split("=", 1) for arg in agent if arg.startswith("--") and "=" in arg)
        node_id, session_dir = opts.get("node-id"), opts.get("session-dir")
        if not node_id or not session_dir:
            return command
        port_file = lambda name: f"--port-file={os.path.join(session_dir, get_port_filename(node_id, name))}"  # noqa: E731
        head = [sys.executable, "-I", "-S"]
        replaced = lean(agent, head, port_file, f"--session-dir={session_dir}")
        return [*command[: at[0]], prefix + subprocess.list2cmdline(replaced), *command[at[0] + 1 :]]

    names = (METRICS_AGENT_PORT_NAME, METRICS_EXPORT_PORT_NAME, DASHBOARD_AGENT_LISTEN_PORT_NAME)
    raylet_command = rewrite(
        raylet_command,
        _DASHBOARD_AGENT_ARG,
        lambda agent, head, port_file, where: [*head, str(IDLE_AGENT), where, *map(port_file, names)],
    )
    return rewrite(
        raylet_command,
        _RUNTIME_ENV_AGENT_ARG,
        lambda agent, head, port_file, where: [
            *head,
            str(LAZY_AGENT),
            port_file(RUNTIME_ENV_AGENT_PORT_NAME),
            where,
            "--",
            *agent,
        ],
    )
