"""Shared test configuration: data folders from ../shared, offline litellm."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = (REPO / ".." / "shared" / "data").resolve()

os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
os.environ.setdefault("ROBOTOUILLE_DATA", str(SHARED_DATA / "robotouille"))
os.environ.setdefault("ALFWORLD_DATA", str(SHARED_DATA / "alfworld"))
# the level an in-process `recap` command sets (workers/log_setup.py) when none is asked for, set
# before the session's cluster starts: its workers then have the same variables as the runs
# (pipeline.raysetup.actor_runtime_env), which start their actors without a runtime_env
os.environ.setdefault("RECAP_LOG_LEVEL", "warning")
if os.environ.get("PYTEST_XDIST_WORKER"):
    # pytest-xdist's workers start with COLUMNS=80 and LINES=24 of their own; the CLI fits its
    # tables to $COLUMNS, so a test would see another width under -n than alone. Tests that care
    # set COLUMNS themselves (monkeypatch).
    for _name in ("COLUMNS", "LINES"):
        os.environ.pop(_name, None)

# the full method registry in every test process, as the CLI and the episode workers have it:
# workers/agents registers mini_swe (recap/ registers the six built-in methods itself)
import workers.agents  # noqa: E402,F401

if os.environ.get("RECAP_SKIP_BWRAP") == "1":
    # the explicit opt-out of the bubblewrap tests (scripts/test.sh): the other tests that open a
    # local sandbox in this process run it as a sweep with `sandbox_trust: none` would (bubblewrap
    # still confines them where it works)
    import workers.sandbox.local_sandbox as _local_sandbox

    _local_sandbox.DEFAULT_TRUST = "none"


@pytest.fixture(scope="session")
def ray_address() -> Iterator[str]:
    """The local Ray cluster (2 CPUs) of this test process, started once and shared by every test
    that runs a sweep in-process or joins it with ``--address``: a Ray start costs seconds, so one
    per session instead of one per module. Under pytest-xdist each worker process has its own
    cluster (its own temp folder and ports, :func:`pipeline.raysetup.init_ray`). Shut down at the
    end only if this fixture started it."""
    import ray

    from pipeline.raysetup import init_ray, shutdown_ray
    from pipeline.spec import RaySpec

    # one sandbox slot per node (ray.sandboxes_per_node): a coding sweep that asks for the bound runs one worker here
    spec = RaySpec(num_cpus=2, sandboxes_per_node=1)
    try:
        started = init_ray(spec)
    except Exception as exc:
        # Ray gives its raylet 30 s to register (ray/_private/node.py); on a machine loaded by other
        # work (the Docker tests beside it under scripts/test.sh's two processes) it can miss that
        # once. init_ray has stopped what it started: start again, once.
        if "timed out during startup" not in str(exc):
            raise
        started = init_ray(spec)
    yield ray.get_runtime_context().gcs_address
    if started:
        shutdown_ray()


@pytest.fixture
def cluster_env(ray_address, monkeypatch) -> dict[str, str]:
    """This process's environment put back to the variables the session's cluster was started with
    (a test before may have changed one for good, e.g. an in-process ``recap --log-level``):
    :func:`pipeline.raysetup.actor_runtime_env` is then None. Returns those variables."""
    from pipeline import raysetup

    started = dict(raysetup._started_env or {})
    assert started, "the session's Ray cluster was not started by init_ray in this process"
    for name in (*raysetup.forwarded_vars(), "PYTHONPATH"):
        if name in started and name != "PYTHONPATH":
            monkeypatch.setenv(name, started[name])
        elif name != "PYTHONPATH":
            monkeypatch.delenv(name, raising=False)
    # PYTHONPATH: runtime_env() puts the project root first, then this process's own entries
    rest = [p for p in started["PYTHONPATH"].split(os.pathsep) if p and p != str(REPO)]
    if rest:
        monkeypatch.setenv("PYTHONPATH", os.pathsep.join(rest))
    else:
        monkeypatch.delenv("PYTHONPATH", raising=False)
    return started


#: fixtures whose one expensive run (a sweep through the pipeline) is shared by the tests that only
#: read it: under pytest-xdist (``--dist loadgroup``) the tests using one of them go to one worker,
#: so the run is made once, not once per worker
SHARED_RUNS = ("pipeline_run", "real_runs")


#: the xdist group of the Docker tests that run a sweep on Ray: scripts/test.sh runs the Docker tests
#: in two processes, and one Ray cluster for them is enough (a second one, started beside Docker
#: containers, only adds a cluster's start-up and background load)
DOCKER_RAY_GROUP = "docker_ray"


@pytest.hookimpl(tryfirst=True)  # before xdist reads the groups into the test ids
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Put each test that reads a shared run into that run's xdist group, and each Docker test on
    Ray without a group of its own into :data:`DOCKER_RAY_GROUP` (no effect without xdist)."""
    for item in items:
        names = getattr(item, "fixturenames", ())
        for name in SHARED_RUNS:
            if name in names:
                item.add_marker(pytest.mark.xdist_group(name))
                break
        else:
            if "ray_address" in names and item.get_closest_marker("docker") and not item.get_closest_marker("xdist_group"):
                item.add_marker(pytest.mark.xdist_group(DOCKER_RAY_GROUP))


@pytest.fixture(autouse=True)
def _reset_our_loggers():
    """``recap`` commands run in-process set our packages' log level and stream handler
    (workers.log_setup); put them back after each test, so a later test's log capture sees every
    record as if no command had run before it."""
    import logging

    from workers.log_setup import PACKAGES

    yield
    for package in PACKAGES:
        logger = logging.getLogger(package)
        logger.setLevel(logging.NOTSET)
        for h in [h for h in logger.handlers if getattr(h, "_recap", False)]:
            logger.removeHandler(h)


@pytest.fixture
def fake_server() -> Iterator:
    """``fake_server(**config)`` starts a loopback fake server (stopped after the test)."""
    from workers.llm.offline.fake_server import FakeServer, FakeServerConfig

    servers: list[FakeServer] = []

    def start(**config) -> FakeServer:
        server = FakeServer(FakeServerConfig(**config))
        server.start_in_thread()
        servers.append(server)
        return server

    yield start
    for s in servers:
        s.stop_thread()


@pytest.fixture(scope="session")
def docker_ready() -> str:
    """(Docker tests) The sandbox image's tag once the daemon answers and the image exists (built if missing)."""
    if os.environ.get("RECAP_SKIP_DOCKER") == "1":
        pytest.skip("RECAP_SKIP_DOCKER=1: docker sandbox tests skipped")
    from workers.sandbox import SandboxError
    from workers.sandbox.docker_sandbox import docker_client
    from workers.sandbox.image import DEFAULT_IMAGE, build_image

    try:
        docker_client()
    except SandboxError as e:
        pytest.fail(f"docker sandbox tests need Docker: {e} (RECAP_SKIP_DOCKER=1 skips them)", pytrace=False)
    try:
        build_image(DEFAULT_IMAGE)
    except Exception as e:
        pytest.fail(f"building {DEFAULT_IMAGE} failed: {e} (RECAP_SKIP_DOCKER=1 skips docker tests)", pytrace=False)
    return DEFAULT_IMAGE


@pytest.fixture(scope="session")
def bwrap_ready() -> None:
    """(Local sandbox tests) bubblewrap confines commands here; a test that needs it FAILS without
    it (scripts/test.sh installs it where it can), RECAP_SKIP_BWRAP=1 is the explicit opt-out."""
    if os.environ.get("RECAP_SKIP_BWRAP") == "1":
        pytest.skip("RECAP_SKIP_BWRAP=1: bubblewrap sandbox tests skipped")
    from workers.sandbox import bwrap

    why = bwrap.probe()
    if why is not None:
        pytest.fail(f"the local sandbox tests need bubblewrap: {why} (RECAP_SKIP_BWRAP=1 skips them)", pytrace=False)
