"""The sequential baselines' exact episodes (ReAct, Act, CoT, Standard), every baseline's
demonstration, and the method registry."""

from __future__ import annotations

import json

import pytest

from recap.baselines import ActAgent, ADaPTAgent, ADaPTConfig, CoTAgent, PlanConfig, ReActAgent, ReActConfig, StandardAgent
from recap.blocksworld import BENCHMARK, DEMONSTRATION, RULES
from recap.config import ConfigError
from recap.llm import LLMError
from recap.methods import METHODS, make_agent
from recap.recap_agent import ReCAPAgent
from schemas.records import StepRecord
from tests.recap.baseline_harness import DEMO_ACTIONS, GOAL, obs_after, run_agent

REACT = [dict(r) for r in DEMONSTRATION.replies["react"]]
ACT = [dict(r) for r in DEMONSTRATION.replies["act"]]
OBS = [obs_after(*DEMO_ACTIONS[:i]) for i in range(len(DEMO_ACTIONS) + 1)]

REACT_SYSTEM = (
    "You are an agent that reaches a goal in an environment one action at a time. At every turn "
    "you think about the latest observation, then choose exactly one action; I carry it out and "
    "show you what happened. An action that is not one of the valid actions is not carried out, "
    "and I tell you so.\n\n"
    "Answer every time with one JSON object and nothing else:\n"
    '{"think": "<your reasoning>", "action": "<one valid action>"}\n'
    '- "think": your reasoning before acting: what the goal still needs, what the latest '
    "observation and your earlier steps tell you, and why the action you choose moves you towards "
    "the goal. If your last action was rejected, first work out why it was not valid.\n"
    '- "action": the single next action, written exactly as it appears among the valid actions.'
)
ACT_SYSTEM = (
    "You are an agent that reaches a goal in an environment one action at a time. At every turn "
    "you choose exactly one action; I carry it out and show you what happened. An action that is "
    "not one of the valid actions is not carried out, and I tell you so.\n\n"
    "Answer every time with one JSON object and nothing else:\n"
    '{"action": "<one valid action>"}\n'
    '- "action": the single next action, written exactly as it appears among the valid actions.'
)
PLAN_INTRO = (
    "You are an agent that reaches a goal in an environment. You see the starting state once and "
    "write the complete plan: every action, in order, that takes the environment from this state to "
    "the goal. The actions are then carried out one after another without asking you again, so the "
    "plan must allow for the way each action changes the state.\n\n"
    "Answer with one JSON object and nothing else:\n"
)
PLAN_ACTIONS_LINE = (
    '- "actions": the whole plan, one action per item, each written exactly as the environment\'s '
    "actions are written (no numbering, no comments)."
)
COT_SYSTEM = (
    PLAN_INTRO
    + '{"think": "<your reasoning>", "actions": ["<action>", ...]}\n'
    + '- "think": your reasoning: what the goal requires, which steps get there, and how each action '
    "changes the state that the following actions start from.\n" + PLAN_ACTIONS_LINE
)
STANDARD_SYSTEM = PLAN_INTRO + '{"actions": ["<action>", ...]}\n' + PLAN_ACTIONS_LINE


def task_prompt(system: str, closing: str) -> str:
    return f"{system}\n\nRules of the environment:\n{RULES}\n\nInitial observation:\n{OBS[0]}\n\nYour goal:\n{GOAL}\n\n{closing}"


def expected_steps(actions: list[str]) -> list[StepRecord]:
    return [
        StepRecord("ep", i, i + 1, a, True, OBS[i + 1], i == len(actions) - 1, i == len(actions) - 1, None)
        for i, a in enumerate(actions)
    ]


@pytest.mark.parametrize(
    "agent, script, system",
    [(ReActAgent(), REACT, REACT_SYSTEM), (ActAgent(), ACT, ACT_SYSTEM)],
    ids=["react", "act"],
)
def test_react_and_act_full_episode(agent, script, system):
    run = run_agent(agent, list(script))
    assert run.result.end_reason == "success" and run.result.success
    assert (run.result.steps, run.result.llm_calls, run.result.invalid_actions, run.result.max_depth) == (6, 6, 0, 0)
    expected = [(0, "user", "task", True), (1, "assistant", "reply", False)]
    for i in range(5):
        expected += [(2 + 2 * i, "user", "observation", False), (3 + 2 * i, "assistant", "reply", False)]
    assert run.seq() == expected
    assert run.content(0) == task_prompt(system, "Reply with your first action.")
    # every observation message is exactly the environment's observation after that action
    assert [m.content for m in run.messages if m.kind == "observation"] == [f"Observation:\n{o}" for o in OBS[1:6]]
    assert [json.loads(m.content) for m in run.messages if m.role == "assistant"] == script
    assert run.steps == expected_steps(DEMO_ACTIONS)
    # each call sees the whole history so far (window 64 is not reached), purpose = message kind
    assert run.windows() == [tuple(range(2 * i + 1)) for i in range(6)]
    assert [c.purpose for c in run.calls] == ["task"] + ["observation"] * 5
    assert [c.response_seq for c in run.calls] == [1, 3, 5, 7, 9, 11]
    hints = run.client.requests[1].hints
    assert hints == {
        "style": agent.style,
        "purpose": "observation",
        "reply_fields": agent.reply_fields,
        "task": GOAL,
        "depth": 0,
        "valid_actions": ["put down C", "stack C on A", "stack C on B"],
    }
    assert agent.reply_fields == (("think", "action") if agent.with_think else ("action",))


def test_act_rejects_nothing_extra_but_react_requires_think():
    # ReAct needs "think": a bare action is repaired; Act takes it as is
    run = run_agent(ReActAgent(), [ACT[0], *REACT])
    assert run.messages[2].kind == "repair"
    assert run.messages[2].content == (
        'I could not use your last reply: the JSON object needs a "think" field (a string).\n'
        'Answer again with a single JSON object of the form {"think": "<your reasoning>", "action": "<one valid action>"} and nothing else.'
    )
    assert run.result.end_reason == "success" and run.result.json_repairs == 1


@pytest.mark.parametrize(
    "agent, reply, system",
    [
        (CoTAgent(), dict(DEMONSTRATION.replies["cot"][0]), COT_SYSTEM),
        (StandardAgent(), dict(DEMONSTRATION.replies["standard"][0]), STANDARD_SYSTEM),
    ],
    ids=["cot", "standard"],
)
def test_cot_and_standard_full_episode(agent, reply, system):
    run = run_agent(agent, [reply])
    assert run.result.end_reason == "success"
    assert (run.result.steps, run.result.llm_calls) == (6, 1)
    assert run.seq() == [(0, "user", "task", True), (1, "assistant", "reply", False)]
    assert run.content(0) == task_prompt(system, "Reply with your complete plan.")
    assert json.loads(run.content(1)) == reply
    assert run.steps == expected_steps(DEMO_ACTIONS)
    assert [c.purpose for c in run.calls] == ["task"]


# -- demonstrations ------------------------------------------------------------------------------------

HEADER = "Here is a complete example of the interaction, from the first prompt to the goal being reached."
FOOTER = "[End of example: the goal was reached.]"


@pytest.mark.parametrize("agent", [ReActAgent(), ActAgent()], ids=["react", "act"])
def test_flat_stepwise_demonstration_is_the_agents_own_transcript(agent):
    text = agent.demonstration_text(BENCHMARK.make("blocksworld/3@1"))
    replies = DEMONSTRATION.replies[agent.style]
    parts = [HEADER, f"[Example prompt]\nInitial observation:\n{OBS[0]}\n\nYour goal:\n{GOAL}\n\nReply with your first action."]
    parts.append(f"[Example reply]\n{json.dumps(replies[0])}")
    for obs, r in zip(OBS[1:6], replies[1:]):
        parts += [f"[Example prompt]\nObservation:\n{obs}", f"[Example reply]\n{json.dumps(r)}"]
    assert text == "\n\n".join([*parts, FOOTER])


@pytest.mark.parametrize("agent", [CoTAgent(), StandardAgent()], ids=["cot", "standard"])
def test_plan_demonstration_is_one_prompt_and_the_plan(agent):
    text = agent.demonstration_text(BENCHMARK.make("blocksworld/4@2"))
    reply = DEMONSTRATION.replies[agent.style][0]
    assert text == "\n\n".join(
        [
            HEADER,
            f"[Example prompt]\nInitial observation:\n{OBS[0]}\n\nYour goal:\n{GOAL}\n\nReply with your complete plan.",
            f"[Example reply]\n{json.dumps(reply)}",
            FOOTER,
        ]
    )


#: the methods with a one-shot demonstration (mini_swe, a coding agent, has none: the paper's
#: SWE-bench protocol)
DEMONSTRATED = sorted(m for m in METHODS if m != "mini_swe")


@pytest.mark.parametrize("method", DEMONSTRATED)
def test_every_method_renders_and_pins_its_demonstration(method):
    agent = make_agent(method)
    env = BENCHMARK.make("blocksworld/3@1")
    text = agent.demonstration_text(env)
    assert text.startswith(HEADER) and text.endswith(FOOTER)
    # the first call sees the demonstration pinned first, then the task prompt
    run = run_agent(agent, [LLMError("auth", "stop here")], env=BENCHMARK.make("blocksworld/3@1"), demonstration=True)
    assert (run.result.end_reason, run.result.error_kind) == ("llm_error", "auth")
    assert run.client.requests[0].window_seqs == (0, 1)
    assert run.messages[0].kind == "demonstration" and run.messages[0].pinned
    assert run.messages[0].content == text
    assert run.messages[1].pinned and run.messages[1].kind in ("task", "executor_task")


def test_adapt_planner_demonstration_derives_from_recap_root_decomposition():
    text = ADaPTAgent().render_planner_demonstration(DEMONSTRATION)
    root = DEMONSTRATION.replies["recap"][0]
    reply = {"think": root["think"], "subtasks": root["subtasks"], "logic": "and"}
    assert text == "\n\n".join(
        [
            "Here is an example of a task being broken down into subtasks.",
            f"[Example prompt]\nCurrent observation:\n{OBS[0]}\n\nTask to break down: {GOAL}\n\nWrite the subtasks and how they combine.",
            f"[Example reply]\n{json.dumps(reply)}",
            "[End of example.]",
        ]
    )


# -- registry --------------------------------------------------------------------------------------------


def test_registry_maps_every_method_to_its_agent_and_config():
    assert {m: (a.__name__, c.__name__) for m, (a, c) in METHODS.items()} == {
        "recap": ("ReCAPAgent", "ReCAPConfig"),
        "react": ("ReActAgent", "ReActConfig"),
        "act": ("ActAgent", "ActConfig"),
        "cot": ("CoTAgent", "PlanConfig"),
        "standard": ("StandardAgent", "PlanConfig"),
        "adapt": ("ADaPTAgent", "ADaPTConfig"),
        "mini_swe": ("MiniSweAgent", "MiniSweConfig"),
    }
    for method, (agent_cls, _) in METHODS.items():
        assert agent_cls.style == method


def test_make_agent_applies_profile_ablation_and_settings():
    a = make_agent("react", profile="released", invalid_streak=5)
    assert isinstance(a, ReActAgent) and a.config == ReActConfig(
        window=128,
        temperature=None,
        window_counts_pins=True,
        invalid_streak=5,
        max_tokens=None,
        reply_format="text",
        json_mode=False,
    )
    a = make_agent("adapt", profile="paper", max_depth=4)
    assert isinstance(a, ADaPTAgent) and a.config == ADaPTConfig(window=128, temperature=0.5, max_depth=4, max_tokens=None)
    assert make_agent("standard", on_invalid="skip").config == PlanConfig(on_invalid="skip")
    r = make_agent("recap", ablation="level_3")
    assert isinstance(r, ReCAPAgent) and r.config.max_level == 3
    assert make_agent("cot", ablation="original").config == PlanConfig()


def test_make_agent_rejects_unknown_names_and_bad_values():
    with pytest.raises(
        ConfigError, match=r"^unknown method 'reflexion'; known: recap, react, act, cot, standard, adapt, mini_swe$"
    ):
        make_agent("reflexion")
    with pytest.raises(ConfigError, match=r"^unknown setting\(s\) max_depth for ReActConfig; known: "):
        make_agent("react", max_depth=3)
    with pytest.raises(ConfigError, match=r"^ablation 'no_think' applies to recap only$"):
        make_agent("act", ablation="no_think")
    with pytest.raises(ConfigError, match=r"^unknown profile 'fast'"):
        make_agent("cot", profile="fast")
    with pytest.raises(ConfigError, match=r"^on_invalid must be 'stop' or 'skip', got 'replan'$"):
        make_agent("cot", on_invalid="replan")
    with pytest.raises(ConfigError, match=r"^max_depth must be >= 1"):
        make_agent("adapt", max_depth=0)
    with pytest.raises(ConfigError, match=r"^executor_steps must be >= 1, got 0$"):
        make_agent("adapt", executor_steps=0)
    with pytest.raises(ConfigError, match=r"^invalid_streak must be >= 1 or null, got 0$"):
        make_agent("react", invalid_streak=0)


# -- end to end: an expert-driven model solves a larger instance with the demonstration pinned ----------


@pytest.mark.parametrize("method", ["react", "act", "cot", "standard", "adapt"])
def test_expert_driven_model_solves_a_five_block_instance(method):
    env = BENCHMARK.make("blocksworld/5@2")
    env.reset()
    plan = env.expert_plan()  # followed by step index (replanning from a held block is not stable)

    def expert(request):
        if method in ("cot", "standard"):
            return {"think": "expert plan", "actions": plan} if method == "cot" else {"actions": plan}
        action = plan[env.steps_taken]
        return {"action": action} if method == "act" else {"think": "expert step", "action": action}

    run = run_agent(make_agent(method), [expert] * 40, env=env, demonstration=True)
    assert run.result.end_reason == "success", run.result
    assert run.result.steps == env.optimal_steps == len(plan) == 16
    assert run.result.llm_calls == (1 if method in ("cot", "standard") else 16)
    assert run.messages[0].kind == "demonstration"
