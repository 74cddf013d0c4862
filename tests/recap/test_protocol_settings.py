"""The protocol settings of issue 12: the paper and released profiles per benchmark, the rule
reminder cadence, the released shortcut trace, K with or without pins, ReAct's history modes,
the derived call cap, output caps and truncated replies, and demonstrations that leave
observations out."""

from __future__ import annotations

import json

import pytest

from recap.agent import ElidedObservations
from recap.baselines import ActAgent, ActConfig, ADaPTConfig, CoTAgent, PlanConfig, ReActAgent, ReActConfig, StandardAgent
from recap.blocksworld import BENCHMARK, DEMONSTRATION, RULES
from recap.config import OMITTED_OBSERVATION, ConfigError, ReCAPConfig, build_config
from recap.llm import LLMResponse
from recap.methods import make_agent
from recap.recap_agent import ReCAPAgent
from recap.scripted import ScriptedClient
from schemas.records import MessageRecord
from tests.recap.recap_harness import demo_env, run_recap
from workers.envs.registry import get_benchmark

SCRIPT = DEMONSTRATION.replies["recap"]
REMINDER = f"Reminder of the environment rules:\n{RULES}\n\n"


def reminded_calls(run) -> list[int]:
    """Call indices whose newest prompt starts with the rule reminder."""
    out = []
    for i, req in enumerate(run.client.requests):
        if req.messages[-1].role == "user" and req.messages[-1].content.startswith(REMINDER):
            out.append(i)
    return out


# -- profiles per benchmark ------------------------------------------------------------------
def test_paper_profile_per_method_and_benchmark():
    # K = 64 rounds = 128 messages (one unit of window is a message); no output cap of ours
    recap_r = build_config(ReCAPConfig, "paper", None, get_benchmark("robotouille"))
    assert (recap_r.window, recap_r.temperature, recap_r.window_counts_pins) == (128, 0.5, False)
    assert (recap_r.reminder_on, recap_r.reminder_period, recap_r.shortcut, recap_r.shortcut_trace) == ("calls", 10, True, False)
    assert recap_r.demo_observations == "first" and recap_r.max_tokens is None and recap_r.max_llm_calls is None
    assert build_config(ReCAPConfig, "paper", None, get_benchmark("alfworld")).demo_observations == "all"
    # the released baselines' protocol under both profiles; the paper's temperature
    react_r = build_config(ReActConfig, "paper", None, get_benchmark("robotouille"))
    assert (react_r.history, react_r.window, react_r.window_keeps_first, react_r.context_drop) == ("window", 64, True, 2)
    assert (react_r.invalid_streak, react_r.invalid_rounds, react_r.temperature) == (5, 3, 0.5)
    react_a = build_config(ReActConfig, "paper", None, get_benchmark("alfworld"))
    assert (react_a.history, react_a.window, react_a.window_counts_pins, react_a.invalid_streak) == ("window", 128, True, None)
    assert (react_a.think_actions, react_a.invalid_feedback, react_a.valid_actions) == (True, "explained", "episode")
    assert build_config(ActConfig, "paper", None, get_benchmark("robotouille")).history == "all"
    assert build_config(ActConfig, "paper", None, get_benchmark("alfworld")).history == "all"
    assert build_config(PlanConfig, "paper", None, get_benchmark("robotouille")).max_tokens is None
    generic = build_config(ReActConfig, "paper", None, None)  # no benchmark: generic
    assert (generic.history, generic.think_actions, generic.valid_actions) == ("window", False, None)
    # no profile: every protocol item at its default (today's behaviour)
    plain = build_config(ReActConfig, None, None, get_benchmark("alfworld"))
    assert (plain.history, plain.think_actions, plain.invalid_feedback, plain.valid_actions, plain.max_tokens) == (
        "window",
        False,
        "plain",
        None,
        1024,
    )


def test_released_temperatures_per_method_and_benchmark():
    """Robotouille baselines 0.7 (base_llm.yaml:2), ReCAP none (its calls send none), ALFWorld
    ReAct/Act none (react.py / act.py send none); the paper: 0.5 for every method."""
    got = {
        (cls.__name__, bench): build_config(cls, "released", None, get_benchmark(bench)).temperature
        for cls in (ReCAPConfig, ReActConfig, ActConfig, PlanConfig, ADaPTConfig)
        for bench in ("robotouille", "alfworld")
    }
    assert got == {
        ("ReCAPConfig", "robotouille"): None,
        ("ReCAPConfig", "alfworld"): None,
        ("ReActConfig", "robotouille"): 0.7,
        ("ReActConfig", "alfworld"): None,
        ("ActConfig", "robotouille"): 0.7,
        ("ActConfig", "alfworld"): None,
        ("PlanConfig", "robotouille"): 0.7,
        ("PlanConfig", "alfworld"): None,
        ("ADaPTConfig", "robotouille"): 0.7,
        ("ADaPTConfig", "alfworld"): None,
    }
    for cls in (ReCAPConfig, ReActConfig, ActConfig, PlanConfig, ADaPTConfig):
        for bench in ("robotouille", "alfworld", None):
            assert build_config(cls, "paper", None, get_benchmark(bench) if bench else None).temperature == 0.5


def test_released_profile_per_benchmark_and_ablation():
    r = build_config(ReCAPConfig, "released", None, get_benchmark("robotouille"))
    assert (r.window, r.temperature, r.window_counts_pins) == (128, None, True)
    assert (r.reminder_on, r.reminder_period, r.shortcut, r.shortcut_trace, r.demo_observations) == (
        "iterations",
        10,
        True,
        True,
        "all",
    )
    assert build_config(ReCAPConfig, "released", None, get_benchmark("alfworld")).reminder_period is None
    for ablation in ("no_think", "name_only", "think_many", "level_3"):
        assert build_config(ReCAPConfig, "released", ablation, get_benchmark("robotouille")).shortcut is False
    assert build_config(ReCAPConfig, "released", "original", get_benchmark("robotouille")).shortcut is True
    assert build_config(ReCAPConfig, "paper", "no_think", get_benchmark("robotouille")).shortcut is True
    # explicit settings still win over the profile
    assert build_config(ReCAPConfig, "released", "no_think", get_benchmark("robotouille"), shortcut=True).shortcut is True


@pytest.mark.parametrize(
    "bad", [{"reminder_on": "returns"}, {"demo_observations": "some"}, {"max_tokens": 0}, {"max_llm_calls": 0}]
)
def test_protocol_settings_are_validated(bad):
    with pytest.raises(ConfigError):
        build_config(ReCAPConfig, **bad)
    with pytest.raises(ConfigError):
        build_config(ReActConfig, history="some")


# -- rule reminder cadence -------------------------------------------------------------------
def test_reminder_every_n_calls_goes_on_the_next_prompt():
    run = run_recap(list(SCRIPT), ReCAPConfig(reminder_period=2))
    assert run.result.end_reason == "success" and run.result.llm_calls == 9
    # calls 0..8: task, descend, leaf_done, leaf_judge, nonleaf_done, descend, leaf_done x3
    assert [r.purpose for r in run.client.requests] == [
        "task",
        "descend",
        "leaf_done",
        "leaf_judge",
        "nonleaf_done",
        "descend",
        "leaf_done",
        "leaf_done",
        "leaf_done",
    ]
    assert reminded_calls(run) == [2, 4, 6, 8]


def test_reminder_every_n_iterations_counts_shortcuts_and_descends():
    run = run_recap(list(SCRIPT), ReCAPConfig(reminder_period=2, reminder_on="iterations"))
    assert run.result.end_reason == "success"
    # iterations: 1 descend, 2 shortcut, 3 return (call 2), 4 shortcut, 5 return (call 3),
    # 6 return (call 4), 7 descend (call 5), 8 shortcut, 9 return (call 6), 10 shortcut,
    # 11 return (call 7), 12 shortcut, 13 return (call 8), 14 shortcut (goal)
    assert reminded_calls(run) == [2, 3, 4, 6, 7, 8]


def test_reminder_also_reaches_descend_prompts():
    run = run_recap(list(SCRIPT), ReCAPConfig(reminder_period=5))
    assert reminded_calls(run) == [5]
    assert run.client.requests[5].purpose == "descend"
    assert run.client.requests[5].messages[-1].content == REMINDER + (
        "OK.\n\nYour current task: build B on A and C on B\n\nWrite the list of subtasks for this task."
    )


# -- released shortcut trace -----------------------------------------------------------------
def test_shortcut_trace_records_prompt_and_synthetic_reply_without_a_call():
    run = run_recap(list(SCRIPT), ReCAPConfig(shortcut_trace=True, reminder_period=None))
    assert run.result.end_reason == "success" and run.result.llm_calls == 9
    assert run.kinds()[:10] == [
        "task",
        "reply",
        "descend",
        "reply",
        "descend",
        "shortcut",
        "leaf_done",
        "reply",
        "descend",
        "shortcut",
    ]
    shortcut = [m for m in run.messages if m.kind == "shortcut"]
    assert len(shortcut) == 6 and all(m.role == "assistant" for m in shortcut)
    assert json.loads(shortcut[0].content) == {
        "think": "This task is itself one of the valid actions, so I carry it out directly.",
        "subtasks": ["unstack C from A"],
    }
    assert run.messages[4].content == "OK.\n\nYour current task: unstack C from A\n\nWrite the list of subtasks for this task."
    # the trace is in the window of the next call
    seqs = {m.seq for m in shortcut}
    assert seqs & set(run.client.requests[2].window_seqs) == {shortcut[0].seq}
    # the tree's shortcut node points at its synthetic reply
    node = next(n for n in run.nodes if n.task == "unstack C from A")
    assert (node.versions[0].call_index, node.versions[0].message_seq) == (None, shortcut[0].seq)
    no_think = run_recap(
        [{k: v for k, v in r.items() if k != "think"} for r in SCRIPT],
        ReCAPConfig(shortcut_trace=True, think="none", reminder_period=None),
    )
    assert json.loads([m for m in no_think.messages if m.kind == "shortcut"][0].content) == {"subtasks": ["unstack C from A"]}


def test_without_trace_a_shortcut_leaves_no_message():
    run = run_recap(list(SCRIPT), ReCAPConfig(reminder_period=None))
    assert "shortcut" not in run.kinds() and run.kinds()[:6] == ["task", "reply", "descend", "reply", "leaf_done", "reply"]


# -- K with or without pins ------------------------------------------------------------------
def test_window_counting_pins_leaves_k_minus_two_unpinned_messages():
    env = BENCHMARK.make("blocksworld/5@2")
    env.reset()
    plan = env.expert_plan()
    script = [{"think": f"plan {i}", "subtasks": plan[i:]} for i in range(len(plan))]
    run = run_recap(script, ReCAPConfig(window=6, window_counts_pins=True, reminder_period=None), env=env, demonstration="DEMO")
    assert all(len(r.messages) <= 6 for r in run.client.requests)
    assert run.client.requests[-1].window_seqs == (0, 1, 28, 29, 30, 31)
    env = BENCHMARK.make("blocksworld/5@2")
    env.reset()
    run = run_recap(script, ReCAPConfig(window=6, reminder_period=None), env=env, demonstration="DEMO")
    assert max(len(r.messages) for r in run.client.requests) == 8
    assert run.client.requests[-1].window_seqs == (0, 1, 26, 27, 28, 29, 30, 31)


# -- ReAct: history last | window, give-up rule ----------------------------------------------
REACT = DEMONSTRATION.replies["react"]


def run_flat(agent, replies, env=None, demonstration="DEMO"):
    client = ScriptedClient(replies)
    records: list = []
    result = agent.run(env or demo_env(), client, episode_id="ep", emit=records.append, demonstration=demonstration)
    return result, client, [r for r in records if isinstance(r, MessageRecord)]


def test_react_history_last_sees_only_the_last_reply_and_the_new_observation():
    result, client, msgs = run_flat(ReActAgent(ReActConfig(history="last")), list(REACT))
    assert result.end_reason == "success"
    assert [r.window_seqs for r in client.requests] == [
        (0, 1),
        (0, 1, 2, 3),
        (0, 1, 4, 5),
        (0, 1, 6, 7),
        (0, 1, 8, 9),
        (0, 1, 10, 11),
    ]
    last = client.requests[-1].messages
    assert last[2].role == "assistant" and json.loads(last[2].content)["action"] == "pick up C"
    assert last[3].content.startswith("Observation:\n")
    result, client, _ = run_flat(ReActAgent(ReActConfig(history="window")), list(REACT))
    assert client.requests[-1].window_seqs == tuple(range(12))


def test_react_paper_profile_on_robotouille_gives_up_after_three_rounds_of_five():
    agent = make_agent("react", profile="paper", benchmark=get_benchmark("robotouille"))
    bad = {"think": "try", "action": "fly away"}
    result, client, msgs = run_flat(agent, [bad] * 20)
    assert result.end_reason == "agent_done" and result.llm_calls == 15 and result.invalid_actions == 15
    assert result.error == "3 rounds of 5 consecutive invalid actions"
    # the whole history (15 exchanges stay under 64 messages)
    assert [len(r.window_seqs) for r in client.requests] == [2 + 2 * i for i in range(15)]
    act = make_agent("act", profile="paper", benchmark=get_benchmark("robotouille"))
    assert isinstance(act, ActAgent) and (act.config.history, act.config.invalid_streak) == ("all", 5)


# -- derived call cap --------------------------------------------------------------------------
def test_call_cap_formula_per_method():
    assert ReCAPAgent().call_cap(144) == 3 * 144 + 10 + 3
    assert ReActAgent().call_cap(144) == 2 * 144 + 10 + 3
    assert CoTAgent().call_cap(144) == StandardAgent().call_cap(144) == 1 + 3
    from recap.baselines import ADaPTAgent

    assert ADaPTAgent(ADaPTConfig()).call_cap(144) == 3 * 144 + 10 + 3
    # no method is cut by calls before steps: ReCAP's cap allows >= 2 calls per step
    for steps in (10, 36 * 4, 82 * 4):
        assert ReCAPAgent().call_cap(steps) >= 2 * steps + 3


def test_derived_call_cap_comes_from_the_episode_step_cap():
    env = demo_env()
    env.max_steps = 2  # cap = 3 * 2 + 10 + 3 = 19
    agent = ReCAPAgent(ReCAPConfig())
    assert agent.episode_config(env).max_llm_calls == 19
    loop = [{"think": "x", "subtasks": ["clear block A", "b"]}] + [{"think": "y", "subtasks": ["nope"]}] * 40
    run = run_recap(loop, ReCAPConfig(reminder_period=None), env=env)
    assert run.result.end_reason == "call_cap" and run.result.llm_calls == 19
    assert run.result.error == "19 LLM calls (cap 19)"
    fixed = run_recap(loop, ReCAPConfig(reminder_period=None, max_llm_calls=7), env=demo_env())
    assert fixed.result.end_reason == "call_cap" and fixed.result.llm_calls == 7


# -- output cap: a cut reply ends as truncated -----------------------------------------------
def test_reply_cut_at_the_output_cap_ends_as_truncated_not_json_failure():
    cut = LLMResponse(
        text='{"think": "long plan", "actions": ["unstack C from A", "put d',
        model="m",
        prompt_tokens=10,
        completion_tokens=3072,
        finish_reason="length",
    )
    result, client, msgs = run_flat(CoTAgent(PlanConfig()), [cut])
    assert result.end_reason == "truncated" and result.llm_calls == 1 and result.json_repairs == 0
    assert result.error == "reply cut at the output cap (3072 tokens, max_tokens 3072)"
    assert client.requests[0].max_tokens == 3072
    assert [m.kind for m in msgs] == ["demonstration", "task", "reply"]
    # a complete reply that happens to be short is unaffected
    ok = LLMResponse(text=json.dumps(DEMONSTRATION.replies["cot"][0]), model="m", finish_reason="stop")
    result, _, _ = run_flat(CoTAgent(PlanConfig()), [ok])
    assert result.end_reason == "success"


# -- demonstrations with observations left out ------------------------------------------------
def test_demo_observations_first_keeps_the_first_and_elides_the_rest():
    full = ReActAgent(ReActConfig()).render_demonstration(DEMONSTRATION)
    first = ReActAgent(ReActConfig(demo_observations="first")).render_demonstration(DEMONSTRATION)
    none = ReActAgent(ReActConfig(demo_observations="none")).render_demonstration(DEMONSTRATION)
    start = demo_env().reset().observation
    assert f"Initial observation:\n{start}" in full and f"Initial observation:\n{start}" in first
    assert first.count(OMITTED_OBSERVATION) == 5 and full.count(OMITTED_OBSERVATION) == 0
    assert none.count(OMITTED_OBSERVATION) == 6 and start not in none
    assert first.count(f"Observation:\n{OMITTED_OBSERVATION}") == 5
    assert len(first) < len(full)
    recap_first = ReCAPAgent(ReCAPConfig(demo_observations="first")).render_demonstration(DEMONSTRATION)
    assert recap_first.count(f"Result:\n{OMITTED_OBSERVATION}") == 5  # the 6th action reaches the goal


def test_elided_environment_keeps_what_the_agent_acts_on():
    inner = demo_env()
    env = ElidedObservations(inner, keep_first=False)
    r = env.reset()
    assert r.observation == OMITTED_OBSERVATION and r.valid_actions == ("pick up B", "unstack C from A")
    step = env.step("unstack C from A")
    assert step.observation == OMITTED_OBSERVATION and "put down C" in step.valid_actions
    assert env.max_steps == inner.max_steps and env.steps_taken == 1


def test_history_keep_never_drops_the_first_reply_even_on_a_context_error():
    from recap.history import History

    h = History("ep", 6, keep=1)
    h.pin("user", "task", "t")
    for i in range(5):
        h.add("assistant", "reply", f"r{i}")
        h.add("user", "observation", f"o{i}")
    assert [m.content for m in h.messages()] == ["t", "r0", "o2", "r3", "o3", "r4", "o4"]
    assert h.drop_oldest(32) == 4  # a context-length error: whole pairs after the kept reply
    assert [m.content for m in h.messages()] == ["t", "r0", "o4"]
    with pytest.raises(ValueError, match=r"^keep must be in \[0, window\), got 6$"):
        History("ep", 6, keep=6)
