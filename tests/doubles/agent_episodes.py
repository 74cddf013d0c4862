"""Helpers: play one agent episode through a gateway client and compare it with the llm_calls rows.

Shared by the offline-expert test (default suite) and the real-model check (tests/realmodel).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from schemas.parts import read_table


def play(
    method: str, instance_id: str, inner: Any, episode_id: str, *, offline: bool, settings: dict[str, Any] | None = None
) -> Any:
    """One episode of ``method`` on ``instance_id``; the gateway behind ``inner`` records the calls."""
    from workers.envs.registry import make_env
    from workers.episode_worker import EpisodeClient, build_agent

    env = make_env(instance_id)
    try:
        client = EpisodeClient(inner, env, sampling_seed=0, offline=offline)
        return build_agent(method, settings=settings).run(env, client, episode_id=episode_id)
    finally:
        env.close()


def episode_rows(run_dir: Path, episode_id: str) -> list[dict[str, Any]]:
    rows = read_table(run_dir, "llm_calls")[0].to_pylist()
    return sorted((r for r in rows if r["episode_id"] == episode_id), key=lambda r: r["call_index"])


def assert_every_call_recorded(result: Any, rows: list[dict[str, Any]]) -> None:
    """The gateway's rows account for exactly the calls and tokens the agent reports."""
    from recap.runtime import END_REASONS

    assert result.end_reason in END_REASONS
    assert len(rows) == result.llm_calls
    assert [r["call_index"] for r in rows] == list(range(len(rows)))
    ok = [r for r in rows if r["status"] == "ok"]
    assert sum(r["prompt_tokens"] for r in ok) == result.prompt_tokens
    assert sum(r["completion_tokens"] for r in ok) == result.completion_tokens
    assert all(r["token_count_source"] == "provider" and r["prompt_tokens"] > 0 for r in ok)
    assert all(r["window_seqs"] and r["response_seq"] is not None for r in ok)
