"""ReCAP's controls: rule reminder, sliding window with pins, context-length recovery, JSON
repair and its cap, per-episode caps, model errors, depth cap and every ablation."""

from __future__ import annotations

import pytest

from recap.blocksworld import BENCHMARK, DEMONSTRATION, RULES
from recap.config import ConfigError, ReCAPConfig, build_config
from recap.llm import LLMError
from recap.recap_agent import ReCAPAgent
from tests.recap.recap_harness import demo_env, run_recap

SCRIPT = DEMONSTRATION.replies["recap"]


def flat_plan_script(env) -> list[dict]:
    """The root lists every action; each refinement returns the rest of the list."""
    plan = env.expert_plan()
    replies = [{"think": f"plan {i}", "subtasks": plan[i:]} for i in range(len(plan))]
    return replies


def test_rule_reminder_on_every_tenth_iteration():
    env = BENCHMARK.make("blocksworld/5@2")
    env.reset()
    script = flat_plan_script(env)
    assert len(script) == 16
    run = run_recap(script, env=env)
    assert run.result.end_reason == "success"
    refines = [m for m in run.messages if m.kind in ("leaf_done", "leaf_judge")]
    assert len(refines) == 15
    reminder = f"Reminder of the environment rules:\n{RULES}\n\n"
    assert [r.content.startswith(reminder) for r in refines] == [i == 9 for i in range(15)]
    assert refines[9].content[len(reminder) :].startswith("You have completed the task: ")


def test_reminder_period_is_configurable_and_can_be_off():
    env = BENCHMARK.make("blocksworld/5@2")
    env.reset()
    run = run_recap(flat_plan_script(env), ReCAPConfig(reminder_period=4), env=env)
    refines = [m.content for m in run.messages if m.kind.startswith("leaf_")]
    assert [i for i, c in enumerate(refines) if c.startswith("Reminder")] == [3, 7, 11]
    env = BENCHMARK.make("blocksworld/5@2")
    env.reset()
    run = run_recap(flat_plan_script(env), ReCAPConfig(reminder_period=None), env=env)
    assert not any(m.content.startswith("Reminder") for m in run.messages)


def test_window_keeps_both_pins_and_never_exceeds_k():
    env = BENCHMARK.make("blocksworld/5@2")
    env.reset()
    run = run_recap(flat_plan_script(env), ReCAPConfig(window=4), env=env, demonstration="DEMO TEXT")
    assert run.messages[0].kind == "demonstration" and run.messages[1].kind == "task"
    for req in run.client.requests:
        assert len(req.messages) <= 4 + 2
        assert req.window_seqs[:2] == (0, 1)
    # pair mode: each call sees the pins and the newest K messages (oldest assistant/user pairs dropped)
    assert run.client.requests[-1].window_seqs == (0, 1, 28, 29, 30, 31)
    assert run.client.requests[5].window_seqs == (0, 1, 8, 9, 10, 11)
    assert run.client.requests[1].window_seqs == (0, 1, 2, 3)


def test_block_window_mode_keeps_a_shared_prefix():
    env = BENCHMARK.make("blocksworld/5@2")
    env.reset()
    run = run_recap(flat_plan_script(env), ReCAPConfig(window=8, window_mode="block"), env=env, demonstration="DEMO")
    windows = [r.window_seqs for r in run.client.requests]
    assert all(len(w) <= 10 for w in windows)
    # consecutive calls either extend the previous window or drop a whole block of 4 at once
    for prev, cur in zip(windows, windows[1:]):
        assert cur[: len(prev)] == prev or cur[2] - prev[2] == 4
    assert windows[:6] == [
        (0, 1),
        (0, 1, 2, 3),
        (0, 1, 2, 3, 4, 5),
        (0, 1, 2, 3, 4, 5, 6, 7),
        (0, 1, 2, 3, 4, 5, 6, 7, 8, 9),
        (0, 1, 6, 7, 8, 9, 10, 11),
    ]


def test_context_length_error_drops_oldest_and_retries_keeping_pins():
    script = list(SCRIPT[:4]) + [LLMError("context_length", "too long")] + list(SCRIPT[4:])
    run = run_recap(script, ReCAPConfig(context_drop=32), demonstration="DEMO")
    assert run.result.end_reason == "success" and run.result.llm_calls == 10
    failed, retried = run.client.requests[4], run.client.requests[5]
    assert failed.window_seqs == tuple(range(0, 10))
    assert retried.window_seqs == (0, 1, 9)  # both pins + the pending prompt
    assert retried.purpose == failed.purpose == "nonleaf_done"
    assert [(c.call_index, c.status, c.error_kind) for c in run.calls if c.status == "error"] == [(4, "error", "context_length")]


def test_malformed_json_is_repaired_with_a_reask():
    script = [
        "```json\n{'think': 'fenced, single quotes', 'subtasks': ['clear block A', 'build B on A and C on B',],}\n```",
        "I think we should",
        *SCRIPT[1:],
    ]
    run = run_recap(script)
    assert run.result.end_reason == "success"
    assert run.kinds()[:6] == ["task", "reply", "descend", "reply", "repair", "reply"]
    assert run.messages[4].content == (
        "I could not use your last reply: no JSON object found in the reply; answer with one JSON object.\n"
        'Answer again with a single JSON object of the form {"think": "<your reasoning>", "subtasks": ["<subtask>", ...]} and nothing else.'
    )
    assert run.result.json_repairs == 1 and run.calls[2].purpose == "repair"


def test_json_repair_is_capped():
    script = [{"think": "a", "subtasks": ["clear block A", "b"]}] + ['{"think": "x"}'] * 4
    run = run_recap(script, ReCAPConfig(max_json_repairs=3))
    assert run.result.end_reason == "json_failures" and run.result.llm_calls == 5
    assert run.kinds().count("repair") == 3
    assert 'needs a "subtasks" field' in run.result.error


def test_call_cap_ends_the_episode():
    run = run_recap(list(SCRIPT), ReCAPConfig(max_llm_calls=3))
    assert run.result.end_reason == "call_cap" and run.result.llm_calls == 3 and run.client.remaining == 6


def test_budget_and_model_errors_end_with_their_reason():
    run = run_recap([SCRIPT[0], LLMError("budget", "run cap reached")])
    assert run.result.end_reason == "budget_exhausted" and run.result.error_kind == "budget"
    run = run_recap([SCRIPT[0], LLMError("auth", "bad key")])
    assert run.result.end_reason == "llm_error" and run.result.error_kind == "auth"


def test_step_cap_ends_the_episode():
    env = demo_env()
    env.max_steps = 2
    run = run_recap(list(SCRIPT), env=env)
    assert run.result.end_reason == "step_cap" and run.result.steps == 2


def test_depth_cap_asks_for_a_single_action_and_runs_the_head():
    replies = [
        {"think": "a", "subtasks": ["clear block A", "build"]},
        {"think": "b", "subtasks": ["unstack C from A", "put down C"]},  # at the cap: the head runs
        {"think": "c", "subtasks": ["put down C", "build"]},
    ]
    run = run_recap(replies + [{"think": "d", "subtasks": []}], ReCAPConfig(max_level=2))
    assert run.kinds()[2] == "depth_cap"
    assert run.messages[2].content == (
        "OK.\n\nYour current task: clear block A\n\n"
        "This task may not be broken down any further. Reply with a list holding exactly one action, "
        "copied exactly from the valid actions, that carries out this task."
    )
    assert [s.action for s in run.steps][:1] == ["unstack C from A"]
    assert run.kinds()[4] == "leaf_done"
    assert max(n.depth for n in run.nodes) == 1


def test_depth_cap_invalid_head_is_a_leaf_failure():
    replies = [
        {"think": "a", "subtasks": ["clear block A"]},
        {"think": "b", "subtasks": ["clear A quickly", "x"]},
        {"think": "c", "subtasks": []},
    ]
    run = run_recap(replies, ReCAPConfig(max_level=2))
    assert run.kinds() == ["task", "reply", "depth_cap", "reply", "leaf_fail", "reply"]
    assert run.steps[0].valid is False and run.steps[0].action == "clear A quickly"


def test_no_think_ablation():
    replies = [{"subtasks": r["subtasks"]} for r in SCRIPT]
    run = run_recap(replies, build_config(ReCAPConfig, ablation="no_think"))
    assert run.result.end_reason == "success"
    assert '{"subtasks": ["<subtask>", ...]}' in run.messages[0].content
    assert '"think"' not in run.messages[0].content
    assert "Your reasoning so far" not in run.messages[4].content
    assert "Your remaining subtasks:\n1. put down C" in run.messages[4].content
    assert all(v.think is None for n in run.nodes for v in n.versions)


def test_think_many_ablation_reinjects_every_think():
    run = run_recap(list(SCRIPT), build_config(ReCAPConfig, ablation="think_many"))
    judge = run.messages[6].content
    assert (
        "Your earlier reasoning for this task, oldest first:\n"
        "1. Only C is on A, so moving C to the table clears it.\n"
        "2. I hold C; putting it down leaves A clear."
    ) in judge


def test_name_only_ablation_carries_only_task_names():
    run = run_recap(list(SCRIPT), build_config(ReCAPConfig, ablation="name_only"))
    msg = run.messages[4].content
    assert msg.startswith("You have completed the task: unstack C from A\n\nResult:\n")
    assert "Your current task: clear block A" in msg
    assert "Your reasoning so far" not in msg and "Your remaining subtasks" not in msg


def test_shortcut_off_asks_for_valid_action_children():
    script = [SCRIPT[0], SCRIPT[1], {"think": "it is one action", "subtasks": ["unstack C from A"]}]
    run = run_recap(script + [{"think": "z", "subtasks": []}] * 3, ReCAPConfig(shortcut=False))
    assert run.kinds()[:6] == ["task", "reply", "descend", "reply", "descend", "reply"]
    assert run.messages[4].content == "OK.\n\nYour current task: unstack C from A\n\nWrite the list of subtasks for this task."


def test_profiles_and_bad_settings():
    paper = build_config(ReCAPConfig, profile="paper")
    released = build_config(ReCAPConfig, profile="released")
    # one unit of window is one message: the paper's K = 64 rounds is 128 messages
    assert (paper.window, paper.temperature, paper.max_tokens) == (128, 0.5, None)
    assert (released.window, released.temperature, released.max_tokens) == (128, None, None)
    assert build_config(ReCAPConfig, ablation="level_3").max_level == 3
    with pytest.raises(ConfigError, match="unknown ablation 'level_9'"):
        build_config(ReCAPConfig, ablation="level_9")
    with pytest.raises(ConfigError, match="unknown setting"):
        build_config(ReCAPConfig, windw=3)
    with pytest.raises(ConfigError, match="max_level must be >= 2"):
        ReCAPAgent(ReCAPConfig(max_level=1))


def test_temperature_reaches_the_request():
    run = run_recap(list(SCRIPT), build_config(ReCAPConfig, profile="released"))
    assert {r.temperature for r in run.client.requests} == {None}
    run = run_recap(list(SCRIPT), build_config(ReCAPConfig, profile="paper"))
    assert {r.temperature for r in run.client.requests} == {0.5}


def test_demonstration_is_rendered_by_the_agent_and_pinned():
    env = BENCHMARK.make("blocksworld/3@2")
    env.reset()
    run = run_recap(flat_plan_script(env), env=env, demonstration=True)
    demo = run.messages[0]
    assert demo.pinned and demo.kind == "demonstration"
    assert demo.content.startswith("Here is a complete example of the interaction")
    assert '{"think": "I hold C; stacking it on B finishes the tower.", "subtasks": ["stack C on B"]}' in demo.content
    assert "Rules of the environment" not in demo.content  # rules are sent once, in the task prompt
    # the no_think rendering of the same demonstration drops the thinks
    text = ReCAPAgent(build_config(ReCAPConfig, ablation="no_think")).render_demonstration(DEMONSTRATION)
    assert '"think"' not in text and '{"subtasks": ["stack C on B"]}' in text
