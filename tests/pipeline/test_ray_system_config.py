"""A local Ray started by ``init_ray`` keeps no task events or metrics (pipeline/raysetup.py).

Asserted on what the cluster applied, not on our dict: the settings the GCS was started with
(its ``--config_list`` command-line argument, base64 JSON; the raylet and the workers take
theirs from the GCS) and the values a worker process of the cluster reads from Ray's own config. Without them the GCS kept every
task and actor call of a run for the dashboard (43 -> 170 MB over a 12,000-call soak).
"""

from __future__ import annotations

import pytest

from tests.pipeline.ray_procs import gcs_config, session_cluster

WANTED = {
    "task_events_report_interval_ms": 0,
    "task_events_max_num_task_in_gcs": 1000,
    "enable_timeline": False,
    "enable_metrics_collection": False,
    "agent_register_timeout_ms": 120_000,  # the lazy runtime-env agent's first start (pipeline/lazy_runtime_env_agent.py)
}


@pytest.mark.usefixtures("ray_address")
def test_the_gcs_starts_without_task_events_or_metrics():
    session_dir, _ = session_cluster()
    applied = gcs_config(session_dir)
    assert {k: applied.get(k) for k in WANTED} == WANTED


@pytest.mark.usefixtures("ray_address")
def test_a_worker_reads_the_limits_from_the_cluster():
    import ray

    from pipeline import raysetup

    if raysetup._owned is None:
        pytest.skip("Ray was started outside init_ray in this process")

    @ray.remote(num_cpus=0)
    def applied() -> tuple[int, bool]:
        from ray._raylet import Config  # type: ignore[attr-defined]  # Ray's compiled module: no stubs for it

        return Config.task_events_max_num_task_in_gcs(), Config.enable_timeline()

    assert ray.get(applied.remote(), timeout=60) == (1000, False)


@pytest.mark.usefixtures("ray_address")
def test_workers_start_with_few_malloc_arenas():
    """glibc reads MALLOC_ARENA_MAX once, at the start: it must be in the environment the worker
    process was started with (/proc/self/environ), not only set later in os.environ."""
    import ray

    from pipeline.raysetup import MALLOC_ARENAS, runtime_env

    @ray.remote(num_cpus=0, runtime_env=runtime_env())
    def start_environment() -> str | None:
        with open("/proc/self/environ", "rb") as fh:
            pairs = dict(item.split(b"=", 1) for item in fh.read().split(b"\0") if b"=" in item)
        value = pairs.get(b"MALLOC_ARENA_MAX")
        return None if value is None else value.decode()

    assert ray.get(start_environment.remote(), timeout=120) == MALLOC_ARENAS


def test_a_cluster_started_here_gives_its_workers_the_variables_without_a_runtime_env(cluster_env, monkeypatch):
    """The session's cluster was started by init_ray: its raylet has the workers' variables, so a
    run's actors need no runtime_env (Ray would start each through setup_worker.py, a second
    Python importing Ray); a variable changed since the start sends the whole environment again."""
    import ray

    from pipeline.raysetup import actor_runtime_env, runtime_env

    assert actor_runtime_env() is None
    wanted = runtime_env()["env_vars"]
    assert wanted == cluster_env

    @ray.remote(num_cpus=0)
    def start_environment(names: list[str]) -> dict[str, str | None]:
        with open("/proc/self/environ", "rb") as fh:
            pairs = dict(item.split(b"=", 1) for item in fh.read().split(b"\0") if b"=" in item)
        return {name: (pairs[name.encode()].decode() if name.encode() in pairs else None) for name in names}

    assert ray.get(start_environment.remote(sorted(wanted)), timeout=120) == wanted
    hook = runtime_env()["worker_process_setup_hook"]
    assert actor_runtime_env() is None
    assert actor_runtime_env({"RECAP_SERVICE": "svc-1"}) == {
        "env_vars": {**wanted, "RECAP_SERVICE": "svc-1"},
        "worker_process_setup_hook": hook,
    }
    monkeypatch.setenv("ROBOTOUILLE_DATA", "/elsewhere/robotouille")
    assert actor_runtime_env() == {
        "env_vars": {**wanted, "ROBOTOUILLE_DATA": "/elsewhere/robotouille"},
        "worker_process_setup_hook": hook,
    }
