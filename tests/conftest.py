"""Shared test configuration: data folders from ../shared, offline litellm."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = (REPO / ".." / "shared" / "data").resolve()

os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
os.environ.setdefault("ROBOTOUILLE_DATA", str(SHARED_DATA / "robotouille"))
os.environ.setdefault("ALFWORLD_DATA", str(SHARED_DATA / "alfworld"))


@pytest.fixture(scope="module")
def ray_address():
    """A local Ray cluster (2 CPUs) for a module's end-to-end runs; drivers join it with
    ``--address``. Shut down after the module only if this fixture started it."""
    import ray

    from pipeline.raysetup import init_ray
    from pipeline.spec import RaySpec

    started = init_ray(RaySpec(num_cpus=2))
    yield ray.get_runtime_context().gcs_address
    if started:
        ray.shutdown()
