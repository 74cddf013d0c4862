"""Fixtures of the workers tests (gateway, model clients): a run folder, a fake key, litellm imported once."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.doubles.llm_requests import FAKE_KEY, FAKE_KEY_ENV
from workers.llm.litellm_setup import get_litellm


@pytest.fixture(scope="session", autouse=True)
def _litellm_imported() -> None:
    get_litellm()


@pytest.fixture
def run_dir(tmp_path: Path) -> Path:
    d = tmp_path / "run"
    d.mkdir()
    (d / "run.json").write_text(json.dumps({"run_id": "test-run"}))
    return d


@pytest.fixture
def fake_key(monkeypatch: pytest.MonkeyPatch) -> str:
    monkeypatch.setenv(FAKE_KEY_ENV, FAKE_KEY)
    return FAKE_KEY
