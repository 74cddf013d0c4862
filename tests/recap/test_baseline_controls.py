"""Controls of the sequential baselines: invalid actions in reject and step mode, Robotouille's
give-up rule, the window with both pins, context-length recovery, JSON repair and its cap, the
call and step caps, model and budget errors, and CoT/Standard's open-loop plan policies."""

from __future__ import annotations

import json

import pytest

from recap.baselines import ActAgent, CoTAgent, PlanConfig, ReActAgent, ReActConfig, StandardAgent
from recap.blocksworld import DEMONSTRATION
from recap.llm import LLMError
from schemas.records import StepRecord
from tests.recap.baseline_harness import DEMO_ACTIONS, demo_env, obs_after, run_agent, stepping_env

REACT = [dict(r) for r in DEMONSTRATION.replies["react"]]
OBS = [obs_after(*DEMO_ACTIONS[:i]) for i in range(len(DEMO_ACTIONS) + 1)]


def bad(action: str) -> dict:
    return {"think": "try it", "action": action}


def feedback(action: str, obs: str) -> str:
    return (
        f"Error feedback: '{action}' is not one of the valid actions, so it was not carried out and "
        "nothing changed. Choose an action exactly as it is written among the valid actions.\n\n"
        f"Observation:\n{obs}"
    )


# -- invalid actions -------------------------------------------------------------------------------------


def test_invalid_action_in_reject_mode_gets_error_feedback_and_takes_no_step():
    # a near miss (substring of a valid action) and a wrong block: both rejected by exact lookup
    run = run_agent(ReActAgent(), [REACT[0], bad("put down"), bad("stack C on C"), *REACT[1:]])
    assert run.result.end_reason == "success"
    assert (run.result.steps, run.result.invalid_actions, run.result.llm_calls) == (6, 2, 8)
    assert [(m.seq, m.kind) for m in run.messages[:8]] == [
        (0, "task"),
        (1, "reply"),
        (2, "observation"),
        (3, "reply"),
        (4, "feedback"),
        (5, "reply"),
        (6, "feedback"),
        (7, "reply"),
    ]
    assert run.content(4) == feedback("put down", OBS[1])
    assert run.content(6) == feedback("stack C on C", OBS[1])
    assert run.content(8) == f"Observation:\n{OBS[2]}"
    assert run.steps[:4] == [
        StepRecord("ep", 0, 1, "unstack C from A", True, OBS[1], False, False),
        StepRecord("ep", 1, 1, "put down", False, OBS[1], False, False),
        StepRecord("ep", 2, 1, "stack C on C", False, OBS[1], False, False),
        StepRecord("ep", 3, 2, "put down C", True, OBS[2], False, False),
    ]
    assert [c.purpose for c in run.calls[:4]] == ["task", "observation", "feedback", "feedback"]


def test_invalid_action_in_step_mode_reaches_the_environment():
    run = run_agent(ActAgent(), [{"action": "put down"}, *[{"action": a} for a in DEMO_ACTIONS]], env=stepping_env())
    assert run.result.end_reason == "success"
    assert (run.result.steps, run.result.invalid_actions) == (7, 1)
    assert run.content(2) == "Observation:\nNothing happens."
    assert run.steps[0] == StepRecord("ep", 0, 1, "put down", False, "Nothing happens.", False, False)
    assert run.steps[1] == StepRecord("ep", 1, 2, "unstack C from A", True, OBS[1], False, False)


def test_robotouille_give_up_rule_ends_after_rounds_of_invalid_streaks():
    cfg = ReActConfig(invalid_streak=2, invalid_rounds=2)
    # a valid action between rejections resets the streak
    script = [bad("x"), REACT[0], bad("y"), bad("z"), bad("w"), bad("v")]
    run = run_agent(ReActAgent(cfg), script)
    assert run.result.end_reason == "agent_done"
    assert run.result.error == "2 rounds of 2 consecutive invalid actions"
    assert (run.result.llm_calls, run.result.invalid_actions, run.result.steps) == (6, 5, 1)
    # off by default: the same replies just keep going until the script (here: a model error) ends it
    run = run_agent(ReActAgent(), [*script, LLMError("server_error", "down")])
    assert run.result.end_reason == "llm_error" and run.result.llm_calls == 7


# -- window, context length, repair, caps, errors ---------------------------------------------------------


def test_window_trims_oldest_pairs_and_keeps_both_pins():
    run = run_agent(ReActAgent(ReActConfig(window=4)), list(REACT), demonstration="DEMO TEXT")
    assert run.result.end_reason == "success"
    assert [(m.seq, m.kind, m.pinned) for m in run.messages[:3]] == [
        (0, "demonstration", True),
        (1, "task", True),
        (2, "reply", False),
    ]
    assert run.windows() == [
        (0, 1),
        (0, 1, 2, 3),
        (0, 1, 2, 3, 4, 5),
        (0, 1, 4, 5, 6, 7),
        (0, 1, 6, 7, 8, 9),
        (0, 1, 8, 9, 10, 11),
    ]
    assert run.client.requests[3].messages[0].content == "DEMO TEXT"
    assert all(len(r.messages) <= 6 for r in run.client.requests)


def test_context_length_error_drops_oldest_messages_and_retries():
    script = [*REACT[:4], LLMError("context_length", "too long"), *REACT[4:]]
    run = run_agent(ReActAgent(ReActConfig(context_drop=4)), script, demonstration="DEMO")
    assert run.result.end_reason == "success" and run.result.llm_calls == 7
    # call 4 failed with the full window; its retry (call 5) sees the pins and the rest after 4 dropped
    assert run.windows()[4] == (0, 1, 2, 3, 4, 5, 6, 7, 8, 9)
    assert run.windows()[5] == (0, 1, 6, 7, 8, 9)
    assert [(c.call_index, c.status, c.error_kind) for c in run.calls if c.status == "error"] == [(4, "error", "context_length")]
    assert run.calls[5].purpose == "observation" and run.calls[5].response_seq == 10


def test_context_length_with_nothing_left_to_drop_is_an_llm_error():
    run = run_agent(ReActAgent(), [LLMError("context_length", "huge prompt")])
    assert (run.result.end_reason, run.result.error_kind) == ("llm_error", "context_length")


def test_json_repair_then_success_and_the_repair_cap():
    run = run_agent(ReActAgent(), ["I will unstack C.", *REACT])
    assert run.result.end_reason == "success" and run.result.json_repairs == 1
    assert [(m.seq, m.kind) for m in run.messages[:4]] == [(0, "task"), (1, "reply"), (2, "repair"), (3, "reply")]
    assert run.content(2) == (
        "I could not use your last reply: no JSON object found in the reply; answer with one JSON object.\n"
        'Answer again with a single JSON object of the form {"think": "<your reasoning>", "action": "<one valid action>"} and nothing else.'
    )
    assert run.calls[1].purpose == "repair"
    run = run_agent(ActAgent(ReActConfig(max_json_repairs=2)), ["no", "{]", '{"act": "x"}'])
    assert run.result.end_reason == "json_failures"
    assert run.result.error == 'the JSON object needs a "action" field (a string)'
    assert (run.result.llm_calls, run.result.json_repairs) == (3, 2)


def test_call_cap_ends_the_episode():
    run = run_agent(ReActAgent(ReActConfig(max_llm_calls=3)), [*REACT])
    assert (run.result.end_reason, run.result.error) == ("call_cap", "3 LLM calls (cap 3)")
    assert (run.result.llm_calls, run.result.steps) == (3, 3)


def test_step_cap_ends_the_episode():
    env = demo_env(step_multiplier=0.5)  # 6 optimal steps -> cap 3
    run = run_agent(
        ActAgent(), [{"action": "unstack C from A"}, {"action": "stack C on A"}, {"action": "unstack C from A"}], env=env
    )
    assert (run.result.end_reason, run.result.error) == ("step_cap", "3 steps (cap 3)")
    assert (run.steps[-1].done, run.steps[-1].success, run.result.steps) == (True, False, 3)


def test_budget_error_ends_with_budget_exhausted_and_other_errors_with_llm_error():
    run = run_agent(ReActAgent(), [REACT[0], LLMError("budget", "run budget spent")])
    assert (run.result.end_reason, run.result.error, run.result.error_kind) == ("budget_exhausted", "run budget spent", "budget")
    run = run_agent(CoTAgent(), [LLMError("rate_limit", "slow down", retries=3)])
    assert (run.result.end_reason, run.result.error_kind) == ("llm_error", "rate_limit")
    assert run.calls[0].status == "error" and run.calls[0].retries == 3


# -- CoT / Standard: open-loop plans ----------------------------------------------------------------------


def plan(*actions: str) -> dict:
    return {"think": "the plan", "actions": list(actions)}


def test_cot_stops_at_the_first_invalid_planned_action():
    run = run_agent(CoTAgent(), [plan("unstack C from A", "pick up B", "put down C")])
    assert run.result.end_reason == "agent_done"
    assert run.result.error == "planned action 2 of 3 ('pick up B') is not a valid action; the plan stops"
    assert run.steps == [
        StepRecord("ep", 0, 1, "unstack C from A", True, OBS[1], False, False),
        StepRecord("ep", 1, 1, "pick up B", False, OBS[1], False, False),
    ]
    assert run.result.llm_calls == 1 and len(run.messages) == 2


def test_cot_skip_policy_goes_on_after_an_invalid_planned_action():
    run = run_agent(CoTAgent(PlanConfig(on_invalid="skip")), [plan("unstack C from A", "pick up B", *DEMO_ACTIONS[1:])])
    assert run.result.end_reason == "success"
    assert (run.result.steps, run.result.invalid_actions) == (6, 1)
    assert [s.valid for s in run.steps] == [True, False, True, True, True, True, True]


def test_standard_in_step_mode_sends_invalid_actions_to_the_environment():
    run = run_agent(StandardAgent(), [{"actions": ["pick up C", *DEMO_ACTIONS]}], env=stepping_env())
    assert run.result.end_reason == "success" and run.result.steps == 7
    assert run.steps[0] == StepRecord("ep", 0, 1, "pick up C", False, "Nothing happens.", False, False)


def test_plan_running_out_before_the_goal_ends_with_agent_done():
    run = run_agent(StandardAgent(), [{"actions": DEMO_ACTIONS[:4]}])
    assert (run.result.end_reason, run.result.error) == (
        "agent_done",
        "the plan's 4 action(s) ran out before the goal was reached",
    )
    assert run.result.steps == 4
    run = run_agent(CoTAgent(), [plan()])
    assert (run.result.end_reason, run.result.steps) == ("agent_done", 0)


def test_plan_longer_than_the_step_cap_ends_with_step_cap():
    env = demo_env(step_multiplier=0.5)
    run = run_agent(StandardAgent(), [{"actions": DEMO_ACTIONS}], env=env)
    assert (run.result.end_reason, run.result.steps) == ("step_cap", 3)


def test_plan_reply_shape_is_repaired():
    run = run_agent(StandardAgent(), [{"actions": "unstack C from A"}, {"actions": DEMO_ACTIONS}])
    assert run.result.end_reason == "success"
    assert json.loads(run.content(1)) == {"actions": "unstack C from A"}
    assert run.content(2).startswith('I could not use your last reply: "actions" must be a list of strings, not a single string.')


@pytest.mark.parametrize("agent", [ReActAgent(), CoTAgent()], ids=["react", "cot"])
def test_agent_objects_are_reusable_across_episodes(agent):
    script = REACT if agent.style == "react" else [dict(DEMONSTRATION.replies["cot"][0])]
    first = run_agent(agent, list(script))
    second = run_agent(agent, list(script))
    assert first.result == second.result and [m.content for m in first.messages] == [m.content for m in second.messages]
