"""``reply_format: text``: the released baselines' plain-text replies (recap.baselines.textreply),
ReAct/Act's loop around them, CoT/Standard's whole-plan check, the offline expert speaking the
layouts, and the released profile choosing them."""

from __future__ import annotations

import pytest

from recap.baselines import ActAgent, CoTAgent, PlanConfig, ReActAgent, ReActConfig, StandardAgent
from recap.baselines import text_prompts as T
from recap.baselines.textreply import (
    match_action,
    parse_action_lines,
    parse_plan,
    parse_reasoning_action,
    parse_step_plan,
    parse_think_or_action,
    render,
    unique_match,
)
from recap.blocksworld import RULES
from recap.config import ConfigError
from recap.env import EnvError
from recap.llm import LLMError
from recap.methods import make_agent
from tests.doubles.offline_expert_client import OfflineExpert
from tests.recap.baseline_harness import DEMO_ACTIONS, GOAL, demo_env, obs_after, run_agent, stepping_env
from workers.envs.registry import get_benchmark

TEXT = {"reply_format": "text", "json_mode": False}
OBS = [obs_after(*DEMO_ACTIONS[:i]) for i in range(len(DEMO_ACTIONS) + 1)]

# -- parsing rules (ReAct_agent.py, IO_agent.py, IOCoT_agent.py, ADaPT_agent.py, react.py) --------------


def test_reasoning_runs_to_the_last_action_label_and_the_action_is_the_first_action_line():
    reply = parse_reasoning_action("Reasoning: first\nAction: is a word here\nmore\nAction: pick up B\n", with_think=True)
    assert (reply.think, reply.action, reply.error) == ("first\nAction: is a word here\nmore\n", "is a word here", None)


def test_multi_line_reasoning_and_an_action_on_the_next_line():
    reply = parse_reasoning_action("Reasoning: C is on A.\nSo C moves.\n\nAction:\n  unstack C from A  \n", with_think=True)
    assert (reply.think, reply.action) == ("C is on A.\nSo C moves.\n\n", "unstack C from A")


def test_missing_lines_are_malformed_with_the_release_feedback():
    assert parse_reasoning_action("Action: pick up B", with_think=True).error == (
        "Your reply has no reasoning. Write it on a line that starts with 'Reasoning: '."
    )
    # ReAct's reasoning pattern runs up to an "Action:" anywhere, so a reply without one lacks reasoning
    assert parse_reasoning_action("Reasoning: think first\nthen pick up B", with_think=True).error == (
        "Your reply has no reasoning. Write it on a line that starts with 'Reasoning: '."
    )
    assert parse_reasoning_action("Reasoning: think first, Action: pick up B", with_think=True).error == (
        "Your reply has no action. Write it on a line that starts with 'Action: '."
    )
    # labels count only at the start of a line; Act needs no reasoning
    assert parse_reasoning_action("My Action: pick up B", with_think=False).error is not None
    assert parse_reasoning_action("Action: pick up B", with_think=False).action == "pick up B"
    assert parse_reasoning_action("Reasoning: done\nAction: Finish", with_think=True).finish


def test_matching_ignores_case_and_punctuation_and_takes_the_first_containing_action():
    valid = ("put down C", "stack C on A", "stack C on B")
    assert match_action("Stack C on B.", valid) == "stack C on B"
    assert match_action("'STACK c, on a'", valid) == "stack C on A"
    assert match_action("stack C on", valid) == "stack C on A"  # containment: first of two
    assert match_action("stack D on A", valid) is None
    assert match_action("...", valid) == "put down C"  # all punctuation contains in every action, as released
    # CoT/Standard need exactly one
    assert unique_match("stack C on", valid) is None
    assert unique_match("Put down C!", valid) == "put down C"


def test_plan_and_action_lines():
    assert parse_plan("Some words\nPlan:\npick up B\n  stack B on A  ") == ["pick up B", "stack B on A"]
    assert parse_plan("Plan: pick up B\n") == ["pick up B", ""]  # a trailing line break leaves a blank action
    assert parse_plan("pick up B") is None
    text = "Think first.\nAction: pick up B\nNext state: B held\nAction:  stack B on A\nnot an Action: x"
    assert parse_action_lines(text) == ["pick up B", "stack B on A"]
    assert parse_action_lines("Plan:\npick up B") is None


def test_step_plan_takes_the_first_or_branch_and_keeps_and_order():
    text = "reasoning\nStep 1: clear A\nStep 2: build on the left\nStep 3: build on the right\nStep 4: check\nExecution order: Step 1 AND (Step 2 OR Step 3) AND Step 4"
    assert parse_step_plan(text) == ["clear A", "build on the left", "check"]
    assert parse_step_plan(text.replace("(Step 2 OR Step 3)", "(Step 3 OR Step 2)")) == ["clear A", "build on the right", "check"]
    # a top-level OR runs its first branch only; no order line: number order; unknown step: its label
    assert parse_step_plan("Step 2: b\nStep 1: a\nExecution order: Step 2 OR Step 1") == ["b"]
    assert parse_step_plan("Step 2: b\nStep 1: a") == ["a", "b"]
    assert parse_step_plan("Step 1: a\nExecution order: Step 1 AND Step 7") == ["a", "Step 7"]
    assert parse_step_plan("**Step 1:** a") == []  # a step line must start the line


def test_yao_line_think_or_command():
    assert parse_think_or_action("think: first the fridge\ngo to fridge 1").think == "think: first the fridge"
    assert parse_think_or_action("  go to fridge 1  \nthink: x").action == "go to fridge 1"
    assert parse_think_or_action("assistant: go to fridge 1").action == "go to fridge 1"
    assert parse_think_or_action("\ngo to fridge 1").action == ""  # the stop at the first line break


@pytest.mark.parametrize("layout", ["reasoning_action", "action", "plan", "action_lines", "step_plan"])
def test_renderers_are_read_back_by_the_parsers(layout):
    reply = {"think": "why", "action": "pick up B", "actions": ["pick up B", "stack B on A"], "subtasks": ["x", "y"]}
    text = render(layout, reply)
    if layout in ("reasoning_action", "action"):
        parsed = parse_reasoning_action(text, with_think=layout == "reasoning_action")
        assert parsed.action == "pick up B" and parsed.error is None
    elif layout == "plan":
        assert parse_plan(text) == reply["actions"]
    elif layout == "action_lines":
        assert parse_action_lines(text) == reply["actions"]
    else:
        assert parse_step_plan(text) == ["x", "y"]


# -- settings ---------------------------------------------------------------------------------------------


def test_released_profile_picks_the_release_format_per_method_and_benchmark():
    def fmt(method, bench):
        c = make_agent(method, "released", benchmark=get_benchmark(bench) if bench else None).config
        return (c.reply_format, c.json_mode, getattr(c, "text_layout", None))

    assert fmt("react", "robotouille") == ("text", False, "labelled")
    assert fmt("react", "alfworld") == ("text", False, "yao")
    assert fmt("act", "robotouille") == ("text", False, "labelled")
    assert fmt("act", "alfworld") == ("json", True, "labelled")  # act.py asks for JSON
    assert fmt("cot", "robotouille") == ("text", False, None)
    assert fmt("cot", "alfworld") == ("json", True, None)  # no released I/O agent on ALFWorld
    assert fmt("react", None) == ("text", False, "labelled")
    assert make_agent("react", "paper", benchmark=get_benchmark("robotouille")).config.reply_format == "json"


def test_text_in_json_mode_is_refused():
    with pytest.raises(ConfigError, match=r"^reply_format: text needs json_mode: false"):
        make_agent("react", reply_format="text")
    with pytest.raises(ConfigError, match=r"^reply_format must be json or text, got 'xml'$"):
        make_agent("standard", reply_format="xml", json_mode=False)


# -- ReAct / Act episodes --------------------------------------------------------------------------------

REACT_SYSTEM = (
    "You are an agent working towards a goal in an environment, one action per turn. Each message shows "
    "the current observation (the objects, the goal and the valid actions). Reason about the latest "
    "observation, then name the single action that moves you closest to the goal.\n\n"
    "A message may start with 'Error feedback:', about your previous reply that could not be used (it was "
    "not carried out); the observation after it is unchanged.\n\n"
    "Reply in plain text, exactly in this layout:\nReasoning: <your reasoning>\nAction: <one valid action>"
)


def test_react_text_episode_with_the_offline_expert_exact_messages():
    env = demo_env()
    client = OfflineExpert(env)
    records: list = []
    result = ReActAgent(ReActConfig(**TEXT)).run(env, client, episode_id="ep", emit=records.append, demonstration=False)
    assert (result.end_reason, result.steps, result.llm_calls, result.json_repairs) == ("success", 6, 6, 0)
    msgs = [(m.seq, m.role, m.kind, m.content) for m in records if type(m).__name__ == "MessageRecord"]
    first = f"{REACT_SYSTEM}\n\nRules of the environment:\n{RULES}\n\nObservation:\n{OBS[0]}\n\nGoal: {GOAL}"
    expected = [(0, "user", "task", first)]
    for i, action in enumerate(DEMO_ACTIONS):
        left = len(DEMO_ACTIONS) - i
        expected.append((1 + 2 * i, "assistant", "reply", f"Reasoning: Expert plan: {left} action(s) left.\n\nAction: {action}"))
        if i < len(DEMO_ACTIONS) - 1:
            expected.append((2 + 2 * i, "user", "observation", f"Observation:\n{OBS[i + 1]}"))
    assert msgs == expected
    assert [r.hints["text_layout"] for r in client.requests] == ["reasoning_action"] * 6
    assert {r.json_mode for r in client.requests} == {False}


def test_malformed_and_invalid_replies_get_error_feedback_and_count_towards_the_rounds():
    agent = ActAgent(ReActConfig(**TEXT, invalid_streak=2, invalid_rounds=2))
    run = run_agent(agent, ["I would pick up B", "Action: fly", "Action: Unstack C, from A!", "no", "no"])
    assert (run.result.end_reason, run.result.steps, run.result.llm_calls) == ("agent_done", 1, 5)
    assert run.result.error == "2 rounds of 2 consecutive unusable replies"
    assert [(s.action, s.valid) for s in run.steps] == [("fly", False), ("unstack C from A", True)]
    assert run.content(2) == (
        f"Error feedback: Your reply has no action. Write it on a line that starts with 'Action: '.\n\nObservation:\n{OBS[0]}"
    )
    assert run.content(4) == (
        f"Error feedback: 'fly' does not match any of the valid actions. Choose one of the valid actions.\n\nObservation:\n{OBS[0]}"
    )
    assert run.content(6) == f"Observation:\n{OBS[1]}"
    assert [m.kind for m in run.messages if m.role == "user"] == ["task", "feedback", "feedback", "observation", "feedback"]


def test_finish_ends_a_react_episode():
    run = run_agent(ReActAgent(ReActConfig(**TEXT)), ["Reasoning: nothing to do\nAction: Finish"])
    assert (run.result.end_reason, run.result.error, run.result.steps) == ("agent_done", "the agent replied Finish", 0)


def test_yao_layout_thoughts_get_ok_and_commands_reach_the_game():
    # the text loop answers as the JSON loop does (one wording: ReActAgent.explained_feedback)
    agent = ReActAgent(ReActConfig(**TEXT, text_layout="yao", invalid_feedback="explained"))
    env = stepping_env()
    replies = ["think: C is on A, move it first.\nignored", "unstack c from a", "unstack C from A", RuntimeError_stop()]
    run = run_agent(agent, replies, env=env)
    valid0 = "\n".join(env.reset().valid_actions or ())
    env2 = stepping_env()
    env2.reset()
    after = env2.step("unstack C from A")
    assert (run.result.end_reason, run.result.llm_calls) == ("llm_error", 4)
    assert [(s.action, s.valid) for s in run.steps] == [("unstack c from a", False), ("unstack C from A", True)]
    assert [(m.kind, m.content) for m in run.messages if m.role == "user"][1:] == [
        ("thought", "OK."),
        (
            "feedback",
            "'unstack c from a' is not one of the valid actions, so it changed nothing. Likely causes:\n"
            "1. The command is not an exact copy of a valid action: copy it word for word, numbers included.\n"
            '2. You meant to think rather than act: to think, write the action as "think: <your thought>".\n'
            "3. Something you assumed about the situation does not hold: check the latest observation.\n\n"
            f"Observation:\nNothing happens.\n\nValid actions:\n{valid0}",
        ),
        ("observation", after.observation),
    ]
    assert "Valid Actions:" in after.observation  # the environment's own list, not a second copy


def test_yao_layout_plain_feedback_shows_the_game_answer_alone():
    agent = ReActAgent(ReActConfig(**TEXT, text_layout="yao"))
    run = run_agent(agent, ["unstack c from a", RuntimeError_stop()], env=stepping_env())
    assert [(m.kind, m.content) for m in run.messages if m.role == "user"][1:] == [("observation", "Nothing happens.")]


def RuntimeError_stop() -> LLMError:  # noqa: N802
    """A model error that ends a scripted episode where the test has seen enough."""
    return LLMError("bad_request", "enough")


# -- CoT / Standard: the whole plan first ------------------------------------------------------------------


def test_standard_checks_the_whole_plan_before_running_any_of_it():
    bad = "Plan:\nunstack C from A\nput down C\npick up D\nstack B on A"
    run = run_agent(StandardAgent(PlanConfig(**TEXT)), [bad])
    assert (run.result.end_reason, run.result.steps) == ("agent_done", 0)
    assert run.result.error == "planned action 3 of 4 ('pick up D') does not match exactly one valid action; no action was run"


def test_the_whole_plan_is_checked_also_past_the_goal():
    # the release's engine copy goes on stepping after the goal (IO_agent.py:176-187): an
    # action after it that matches nothing refuses the whole plan; one that matches is checked
    # and the plan runs (the episode ends at the goal)
    past = "Plan:\n" + "\n".join([*DEMO_ACTIONS, "pick up D"])
    run = run_agent(StandardAgent(PlanConfig(**TEXT)), [past])
    assert (run.result.end_reason, run.result.steps) == ("agent_done", 0)
    assert run.result.error == "planned action 7 of 7 ('pick up D') does not match exactly one valid action; no action was run"
    run = run_agent(StandardAgent(PlanConfig(**TEXT)), ["Plan:\n" + "\n".join([*DEMO_ACTIONS, "unstack C from B"])])
    assert (run.result.end_reason, run.result.steps) == ("success", 6)


def test_robotouille_plan_copy_steps_past_the_goal():
    from workers.envs.registry import make_env

    env = make_env("robotouille/synchronous/0_cheese_sandwich@42")
    env.reset()
    plan = env.expert_plan()
    assert plan
    sim = env.plan_copy()
    for action in plan:
        step = sim.step(action)
    assert (step.done, step.success) == (True, True)
    after = sim.step(step.valid_actions[0])  # the copy goes on; the episode's env is untouched
    assert after.valid_actions and env.steps_taken == 0
    with pytest.raises(EnvError, match="the episode is over"):
        done = make_env("robotouille/synchronous/0_cheese_sandwich@42")
        done.reset()
        for action in plan:
            done.step(action)
        done.step(step.valid_actions[0])
    lines = "\n".join([*plan, "Fly to the moon"])
    agent = make_agent("standard", "released", benchmark=get_benchmark("robotouille"))
    env = make_env("robotouille/synchronous/0_cheese_sandwich@42")
    run = run_agent(agent, ["Plan:\n" + lines], env=env)
    assert run.result.error == (
        f"planned action {len(plan) + 1} of {len(plan) + 1} ('Fly to the moon') does not match exactly one "
        "valid action; no action was run"
    )


def test_cot_plan_ignoring_case_and_punctuation_runs_to_the_goal():
    lines = [f"Action: {a.upper()}.\nNext state: something changed" for a in DEMO_ACTIONS]
    run = run_agent(CoTAgent(PlanConfig(**TEXT)), ["I plan it all.\n" + "\n".join(lines)])
    assert (run.result.end_reason, run.result.steps, run.result.llm_calls) == ("success", 6, 1)
    assert [s.action for s in run.steps] == DEMO_ACTIONS


def test_plan_replies_without_a_plan_or_with_an_ambiguous_action_end_the_episode():
    run = run_agent(StandardAgent(PlanConfig(**TEXT)), ["unstack C from A"])
    assert (run.result.end_reason, run.result.error) == ("agent_done", "the reply has no 'Plan:' line; the plan is not run")
    run = run_agent(CoTAgent(PlanConfig(**TEXT)), ["Action: unstack C from A\nAction: stack C on"])
    assert run.result.error == "planned action 2 of 2 ('stack C on') does not match exactly one valid action; no action was run"
    assert run.result.steps == 0


def test_standard_text_episode_with_the_offline_expert_exact_messages():
    env = demo_env()
    records: list = []
    agent = StandardAgent(PlanConfig(**TEXT))
    result = agent.run(env, OfflineExpert(env), episode_id="ep", emit=records.append, demonstration=False)
    assert (result.end_reason, result.steps, result.llm_calls) == ("success", 6, 1)
    msgs = [(m.kind, m.content) for m in records if type(m).__name__ == "MessageRecord"]
    assert msgs == [
        ("task", f"{T.plan_system(False)}\n\nRules of the environment:\n{RULES}\n\nObservation:\n{OBS[0]}\n\nGoal: {GOAL}"),
        ("reply", "Plan:\n" + "\n".join(DEMO_ACTIONS)),
    ]
