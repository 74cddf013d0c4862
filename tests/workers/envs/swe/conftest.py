"""The six fixture repositories, built once per session, and a factory of environments on them."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.workers.envs.swe.sandbox_log import SandboxLog
from workers.envs.registry import make_env
from workers.envs.swe.env import SweEnvironment
from workers.envs.swe.examples import Fixtures, make_fixtures


@pytest.fixture(scope="session")
def fixtures(tmp_path_factory: pytest.TempPathFactory) -> Fixtures:
    return make_fixtures(tmp_path_factory.mktemp("swe-fixtures"))


@pytest.fixture
def sandboxes() -> Iterator[SandboxLog]:
    log = SandboxLog()
    yield log
    for box in log.opened:
        box.close()


@pytest.fixture
def swe_env(fixtures: Fixtures, sandboxes: SandboxLog) -> Iterator[Callable[..., SweEnvironment]]:
    made: list[SweEnvironment] = []

    def make(name: str, **options: Any) -> SweEnvironment:
        env = make_env(f"swe/fixture__{name}-1", instances_file=str(fixtures.tasks_file), open_sandbox=sandboxes, **options)
        assert isinstance(env, SweEnvironment)
        made.append(env)
        return env

    yield make
    for env in made:
        env.close()


def repo_of(fixtures: Fixtures, name: str) -> Path:
    return fixtures.tasks_file.parent / "repos" / name
