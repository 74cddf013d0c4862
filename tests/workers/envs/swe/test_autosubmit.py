"""ReCAP on a SWE-bench fixture (local sandbox) reaching a limit: the diff it leaves is handed in
and graded, and the result says ``autosubmitted`` with the limit first in its error (SWE-agent's
autosubmission, swebench-recap/sweagent/agent/agents.py:1250-1285); with nothing changed the
episode ends at the limit, ungraded."""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

from recap.config import ReCAPConfig
from recap.llm import LLMError, LLMResponse, ToolCall
from recap.recap_agent import ReCAPAgent
from recap.scripted import ScriptedClient
from schemas.outcomes import BudgetRefusal
from schemas.records import EvaluationRecord
from workers.envs.swe.env import SweEnvironment

FIX = json.dumps({"path": "shop.py", "old_str": "{cents / 100}", "new_str": "{cents / 100:.2f}"})
PLAN = json.dumps({"think": "fix the price format", "subtasks": ["fix format_price"]})


def reply(text: str, *calls: tuple[str, str, str], cost: float = 0.03) -> LLMResponse:
    return LLMResponse(
        text=text, model="scripted", tool_calls=tuple(ToolCall.parse(*c) for c in calls), cost_usd=cost, test_double=True
    )


def play(env: SweEnvironment, replies: list[Any], **settings: Any) -> tuple[Any, ScriptedClient, list[EvaluationRecord]]:
    client = ScriptedClient(replies)
    result = ReCAPAgent(ReCAPConfig(window=100, **settings)).run(env, client, episode_id="e")
    rows = env.take_records("e", "r")
    return result, client, rows


def test_the_cost_cap_with_a_diff_grades_the_diff(swe_env: Callable[..., SweEnvironment]) -> None:
    env = swe_env("format")
    replies = [
        reply(PLAN, ("c1", "str_replace", FIX)),  # $0.03
        reply("", ("c2", "bash", json.dumps({"command": "echo checked"}))),  # $0.06: the cap is reached
    ]
    result, client, rows = play(env, replies, max_episode_cost_usd=0.05)
    assert client.remaining == 0 and len(client.requests) == 2  # the third call is never sent
    assert (result.end_reason, result.success, result.error, result.llm_calls, result.steps) == (
        "autosubmitted",
        True,
        "episode_limit: $0.0600 spent (limit $0.05)",
        2,
        2,
    )
    (row,) = rows
    assert (row.episode_id, row.resolved, row.reason, row.fail_to_pass_passed) == ("e", True, "resolved", 1)
    assert '+    return f"${cents / 100:.2f}"' in row.patch


def test_the_gateway_refusing_at_the_per_instance_cap_grades_the_diff(swe_env: Callable[..., SweEnvironment]) -> None:
    env = swe_env("format")
    refusal = BudgetRefusal(scope="episode", model="m", cap_pico=10**13, committed_pico=10**13 - 1, worst_pico=5)
    replies = [reply(PLAN, ("c1", "str_replace", FIX)), LLMError("budget", refusal.message, refusal=refusal)]
    result, _client, rows = play(env, replies)
    assert (result.end_reason, result.success, result.error) == ("autosubmitted", True, f"episode_limit: {refusal.message}")
    assert [r.resolved for r in rows] == [True]


def test_a_context_overflow_grades_a_wrong_diff_as_unresolved(swe_env: Callable[..., SweEnvironment]) -> None:
    env = swe_env("format")
    wrong = json.dumps({"path": "shop.py", "old_str": "{cents / 100}", "new_str": "{cents / 100:.1f}"})
    overflow = LLMError("context_length", "prompt too long")
    result, _client, rows = play(env, [reply(PLAN, ("c1", "str_replace", wrong)), overflow, overflow, overflow])
    assert (result.end_reason, result.success, result.error_kind) == ("autosubmitted", False, "context_length")
    assert result.error == "llm_error: context length exceeded with nothing left to drop"
    (row,) = rows
    assert (row.resolved, row.reason) == (False, "tests_failed")


def test_the_call_cap_with_a_diff_grades_the_diff(swe_env: Callable[..., SweEnvironment]) -> None:
    env = swe_env("format")
    result, _client, rows = play(env, [reply(PLAN, ("c1", "str_replace", FIX))], max_llm_calls=1)
    assert (result.end_reason, result.success, result.error) == ("autosubmitted", True, "call_cap: 1 LLM calls (cap 1)")
    assert [r.resolved for r in rows] == [True]


def test_a_limit_without_changes_ends_ungraded(swe_env: Callable[..., SweEnvironment]) -> None:
    env = swe_env("format")
    replies = [reply(PLAN, ("c1", "bash", json.dumps({"command": "ls"})), cost=0.06)]
    result, _client, rows = play(env, replies, max_episode_cost_usd=0.05)
    assert (result.end_reason, result.success, result.error) == ("episode_limit", False, "$0.0600 spent (limit $0.05)")
    assert rows == []


def test_the_sandbox_command_limit_with_a_diff_grades_the_diff(swe_env: Callable[..., SweEnvironment]) -> None:
    env = swe_env("format", max_commands=1)
    result, _client, rows = play(env, [reply(PLAN, ("c1", "str_replace", FIX))])
    assert (result.end_reason, result.success, result.error) == ("autosubmitted", True, "step_cap: 1 steps (cap 1)")
    assert [r.resolved for r in rows] == [True]


def test_released_recap_on_swe_has_the_release_cap_and_whole_history_and_paper_keeps_its_own() -> None:
    from recap.config import ReCAPConfig, build_config
    from workers.envs.registry import get_benchmark

    swe = get_benchmark("swe")
    released = build_config(ReCAPConfig, profile="released", benchmark=swe)
    assert isinstance(released, ReCAPConfig)
    assert (
        released.max_episode_cost_usd,
        released.window,
        released.context_overflow,
        released.tool_calls_per_reply,
        released.reply_schema,
        released.temperature,
    ) == (10.0, 100_000, "end", "one", True, 0.0)
    paper = build_config(ReCAPConfig, profile="paper", benchmark=swe)
    assert isinstance(paper, ReCAPConfig)
    assert (paper.max_episode_cost_usd, paper.window, paper.context_overflow, paper.tool_calls_per_reply, paper.reply_schema) == (
        None,
        128,
        "drop",
        "any",
        False,
    )
    # the settings added here are left out of a paper config's JSON (unit hashes planned before them stay)
    assert not {"context_overflow", "tool_calls_per_reply", "reply_schema"} & set(json.loads(paper.to_json()))
    assert ReCAPConfig.from_json(paper.to_json()) == paper and ReCAPConfig.from_json(released.to_json()) == released
    # a sweep's limits.usd still wins over the release's $10
    assert build_config(ReCAPConfig, profile="released", benchmark=swe, max_episode_cost_usd=3.0).max_episode_cost_usd == 3.0


def test_under_context_overflow_end_the_first_overflow_ends_and_hands_in(swe_env: Callable[..., SweEnvironment]) -> None:
    env = swe_env("format")
    overflow = LLMError("context_length", "prompt too long")
    result, client, rows = play(env, [reply(PLAN, ("c1", "str_replace", FIX)), overflow], context_overflow="end")
    assert client.remaining == 0 and len(client.requests) == 2  # nothing dropped, no call again
    assert (result.end_reason, result.success, result.error) == (
        "autosubmitted",
        True,
        "llm_error: context length exceeded (the whole history is kept)",
    )
    assert [r.resolved for r in rows] == [True]


def test_released_recap_on_a_fixture_one_call_schema_and_the_ten_dollar_cap(swe_env: Callable[..., SweEnvironment]) -> None:
    from recap.methods import make_agent
    from workers.envs.registry import get_benchmark

    env = swe_env("format")
    agent = make_agent("recap", profile="released", benchmark=get_benchmark("swe"))
    two = reply(PLAN, ("c1", "view", json.dumps({"path": "shop.py"})), ("c2", "str_replace", FIX), cost=1.0)
    replies = [
        two,  # re-asked: one call per reply
        reply(PLAN, ("c3", "str_replace", FIX), cost=6.0),
        reply("", ("c4", "bash", json.dumps({"command": "cd tests && export X=1"})), cost=4.0),  # $11: past the $10 cap
    ]
    client = ScriptedClient(replies)
    result = agent.run(env, client, episode_id="e", demonstration=False)
    rows = env.take_records("e", "r")
    assert [r.purpose for r in client.requests] == ["task", "repair", "action_taken"]
    assert all(r.response_schema is not None for r in client.requests)
    assert (result.end_reason, result.success, result.error, result.json_repairs) == (
        "autosubmitted",
        True,
        "episode_limit: $11.0000 spent (limit $10.0)",
        1,
    )
    assert [r.resolved for r in rows] == [True]
