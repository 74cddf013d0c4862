"""Fixtures of the gateway tests: a fake server per test, a run folder, requests, a fake key."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from recap.llm import ChatMessage, LLMRequest
from workers.llm.litellm_setup import get_litellm

#: a fake API key; tests check it never reaches a written file
FAKE_KEY = "sk-test-FAKEKEY-a1b2c3d4e5f6g7h8"
FAKE_KEY_ENV = "RECAP_TEST_FAKE_KEY"


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


def make_request(
    i: int, content: str | None = None, *, episode: str = "ep", hints=None, max_tokens: int | None = None, window=None
) -> LLMRequest:
    return LLMRequest(
        messages=(ChatMessage("user", content if content is not None else f"request number {i}"),),
        episode_id=episode,
        call_index=i,
        purpose="task",
        window_seqs=tuple(window) if window is not None else (i,),
        node_id=0,
        response_seq=i + 1,
        max_tokens=max_tokens,
        hints=hints or {},
    )
