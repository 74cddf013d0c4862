"""Fixtures of the FEVER tests: a tiny claims folder, the Wikipedia stand-in, environments on it."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import pytest

from workers.envs.fever import BENCHMARK, FeverEnvironment
from workers.envs.fever.pages import MemoryPageStore
from workers.envs.fever.ratelimit import TokenBucket
from workers.envs.fever.standin import StandIn

CLAIMS = [
    {
        "id": 1001,
        "verifiable": "VERIFIABLE",
        "label": "SUPPORTS",
        "claim": "Nikolaj Coster-Waldau worked with the Fox Broadcasting Company.",
    },
    {"id": 1002, "verifiable": "VERIFIABLE", "label": "REFUTES", "claim": "Mercury is a city."},
    {"id": 1003, "verifiable": "NOT VERIFIABLE", "label": "NOT ENOUGH INFO", "claim": "Xyzzy qwerty is a word."},
]


@pytest.fixture
def claims_dir(tmp_path: Path) -> Path:
    folder = tmp_path / "fever-data"
    folder.mkdir()
    (folder / "paper_dev.jsonl").write_text("".join(json.dumps(c) + "\n" for c in CLAIMS), encoding="utf-8")
    return folder


@pytest.fixture
def standin() -> Iterator[StandIn]:
    server = StandIn().start()
    yield server
    server.stop()


@pytest.fixture
def store() -> MemoryPageStore:
    return MemoryPageStore()


@pytest.fixture
def make(claims_dir: Path, standin: StandIn, store: MemoryPageStore):
    """``make(claim_id, **options)``: an environment on the stand-in, recording into ``store``, no rate-limit waits."""

    def build(claim_id: int, **options) -> FeverEnvironment:
        if "wikipedia_url" not in options:
            options["wikipedia_url"] = standin.base_url
        options.setdefault("limiter", TokenBucket(1000.0, 1000))
        options.setdefault("page_store", store)
        env = BENCHMARK.make(f"fever/{claim_id}", data_dir=str(claims_dir), **options)
        assert isinstance(env, FeverEnvironment)
        return env

    return build
