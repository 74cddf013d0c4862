"""A model's hostile tool calls on a docker sandbox (issue 35 items 2-5): each is refused or
stays in its bounds, through the environment's step path, and the episode goes on (never
``env_error``). The attacks are in :mod:`tests.workers.envs.swe.hostile_tools`, shared with the
chaos lab's ``sandbox_docker`` scenario."""

from __future__ import annotations

import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.workers.envs.swe import hostile_tools as H
from workers.envs.swe.env import SweEnvironment
from workers.sandbox import LABEL_RUN, remove_labelled

# one xdist worker for the module: its one episode (a container) serves every attack
pytestmark = [pytest.mark.docker, pytest.mark.xdist_group("swe_hostile_tools")]


@pytest.fixture(scope="module")
def tasks_file(tmp_path_factory: pytest.TempPathFactory, docker_ready: str) -> Path:
    return H.hostile_repo(tmp_path_factory.mktemp("hostile"))


@pytest.fixture(scope="module")
def env(tasks_file: Path) -> Iterator[SweEnvironment]:
    """One episode for all the attacks (each leaves the repository usable for the next)."""
    labels = {LABEL_RUN: f"test-{uuid.uuid4().hex[:12]}"}
    e = H.docker_env(tasks_file, labels, max_commands=500)
    yield e
    e.close()
    remove_labelled(labels)


@pytest.mark.parametrize("name", list(H.TOOL_ATTACKS))
def test_a_hostile_tool_call_is_refused_and_the_episode_goes_on(env: SweEnvironment, name: str) -> None:
    held, detail = H.TOOL_ATTACKS[name](env)
    assert held, detail


# measures the growth of /var/lib/docker as a whole: no other container may write beside it
@pytest.mark.host_load
def test_every_writable_place_of_a_container_is_bounded(tmp_path: Path, docker_ready: str) -> None:
    results = H.disk_writes_to_every_place(tmp_path)
    assert list(results) == [f"disk: 75 MB to {p}" for p in H.PLACES] + ["disk: /var/lib/docker growth"]
    failed = {name: detail for name, (held, detail) in results.items() if not held}
    assert not failed, failed
