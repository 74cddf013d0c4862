"""ADaPT: executor first, planning only on failure, AND/OR combination, the depth cap, the
executor's budget and patience, isolated contexts, reply shapes, demonstrations and records."""

from __future__ import annotations

import json

import pytest

from recap.baselines import ADaPTAgent, ADaPTConfig
from recap.blocksworld import DEMONSTRATION, RULES, BlocksworldEnv
from recap.llm import LLMError
from schemas.records import NodeRecord, NodeVersion, StepRecord
from tests.recap.baseline_harness import DEMO_ACTIONS, GOAL, obs_after, run_agent, stepping_env

REACT = [dict(r) for r in DEMONSTRATION.replies["react"]]
OBS = [obs_after(*DEMO_ACTIONS[:i]) for i in range(len(DEMO_ACTIONS) + 1)]

EXECUTOR_SYSTEM = (
    "You are the executor of a planning system: you carry out one task in an environment, one action "
    "at a time. After each action I show you what happened. An action that is not one of the valid "
    "actions is not carried out, and I tell you so. You see only your own task; it may be one part of "
    "a larger goal, so do what the task asks and then stop.\n\n"
    "Answer every time with one JSON object and nothing else, in one of these forms:\n"
    '{"think": "<your reasoning>", "action": "<one valid action>"} to take the next action;\n'
    '{"think": "<your reasoning>", "status": "done"} once the task is finished, or\n'
    '{"think": "<your reasoning>", "status": "failed"} if, after trying your best, you conclude that '
    "the task cannot be carried out.\n"
    '- "think": your reasoning about the task, the latest observation and your next move.\n'
    '- "action": written exactly as it appears among the valid actions.\n'
    '- "status": only when you stop working on the task; never together with an action.'
)
PLANNER_SYSTEM = (
    "You are the planner of a planning system. An executor tried to carry out a task in an environment "
    "and did not manage it on its own. Break the task into a short list of simpler subtasks (usually "
    "two to four). Each subtask goes to an executor that sees only that subtask and the environment, "
    "not the task above it nor the other subtasks, so every subtask must make sense by itself and name "
    "the objects it concerns. A subtask that is still too hard is broken down again in the same way.\n\n"
    "Answer with one JSON object and nothing else:\n"
    '{"think": "<your reasoning>", "subtasks": ["<subtask>", ...], "logic": "and" or "or"}\n'
    '- "think": your reasoning about what the task needs, given the current observation.\n'
    '- "subtasks": the subtasks, in the order they should be attempted.\n'
    '- "logic": "and" when every subtask must succeed (they run in order and the task fails at the '
    'first one that fails); "or" when the subtasks are alternatives (they are tried in order until one succeeds).'
)
RULES_PART = f"Rules of the environment:\n{RULES}"
EXEC_CLOSING = "Reply with your first action, or with a status if the task needs no action."


def executor_prompt(task: str, obs: str, last: str | None = None) -> str:
    situation = ([f"Last action taken in the environment: {last}"] if last else []) + [f"Current observation:\n{obs}"]
    return "\n\n".join([EXECUTOR_SYSTEM, RULES_PART, *situation, f"Your task: {task}", EXEC_CLOSING])


def planner_prompt(task: str, obs: str, last: str | None = None) -> str:
    situation = ([f"Last action taken in the environment: {last}"] if last else []) + [f"Current observation:\n{obs}"]
    return "\n\n".join(
        [PLANNER_SYSTEM, RULES_PART, *situation, f"Task to break down: {task}", "Write the subtasks and how they combine."]
    )


FAILED = {"think": "this is more than I can do in one go", "status": "failed"}
DONE = {"think": "that part is finished", "status": "done"}
SPLIT = {"think": "clear A first, then build", "subtasks": ["clear block A", "build the tower"], "logic": "and"}


def node(node_id, parent, depth, child, task, kind, status, versions=()):
    return NodeRecord("ep", node_id, parent, depth, child, task, kind, status, tuple(versions), None)


# -- control flow ------------------------------------------------------------------------------------------


def test_executor_alone_solves_the_task_without_planning():
    run = run_agent(ADaPTAgent(), list(REACT))
    assert run.result.end_reason == "success"
    assert (run.result.steps, run.result.llm_calls, run.result.max_depth) == (6, 6, 0)
    expected = [(0, "user", "executor_task", True), (1, "assistant", "reply", False)]
    for i in range(5):
        expected += [(2 + 2 * i, "user", "observation", False), (3 + 2 * i, "assistant", "reply", False)]
    assert run.seq() == expected
    assert run.content(0) == executor_prompt(GOAL, OBS[0])
    assert [m.content for m in run.messages if m.kind == "observation"] == [f"Observation:\n{o}" for o in OBS[1:6]]
    assert run.windows() == [tuple(range(2 * i + 1)) for i in range(6)]
    assert run.nodes == [node(0, None, 0, 0, GOAL, "root", "open")]
    assert [s.node_id for s in run.steps] == [0] * 6
    assert run.client.requests[0].hints == {
        "style": "adapt",
        "purpose": "executor_task",
        "reply_fields": ("think", "action"),
        "role": "executor",
        "task": GOAL,
        "depth": 0,
        "valid_actions": ["pick up B", "unstack C from A"],
    }


def test_executor_failure_then_and_decomposition_runs_subtasks_in_isolated_contexts():
    script = [FAILED, SPLIT, REACT[0], REACT[1], DONE, *REACT[2:]]
    run = run_agent(ADaPTAgent(), script)
    assert run.result.end_reason == "success"
    assert (run.result.steps, run.result.llm_calls, run.result.max_depth) == (6, 9, 1)
    assert [(m.seq, m.kind, m.pinned) for m in run.messages] == [
        (0, "executor_task", True),
        (1, "reply", False),  # root executor (main context)
        (2, "planner_task", True),
        (3, "reply", False),  # planner (own context)
        (4, "executor_task", True),
        (5, "reply", False),
        (6, "observation", False),
        (7, "reply", False),
        (8, "observation", False),
        (9, "reply", False),  # executor for "clear block A"
        (10, "executor_task", True),
        (11, "reply", False),
        (12, "observation", False),
        (13, "reply", False),
        (14, "observation", False),
        (15, "reply", False),
        (16, "observation", False),
        (17, "reply", False),
    ]
    assert run.content(2) == planner_prompt(GOAL, OBS[0])
    assert run.content(4) == executor_prompt("clear block A", OBS[0])
    # the next executor sees only its own task, the last action and the current observation
    assert run.content(10) == executor_prompt("build the tower", OBS[2], last="put down C")
    # each context sees only its own messages
    assert run.windows() == [
        (0,),
        (2,),
        (4,),
        (4, 5, 6),
        (4, 5, 6, 7, 8),
        (10,),
        (10, 11, 12),
        (10, 11, 12, 13, 14),
        tuple(range(10, 17)),
    ]
    assert [c.purpose for c in run.calls] == [
        "executor_task",
        "planner_task",
        "executor_task",
        "observation",
        "observation",
        "executor_task",
        "observation",
        "observation",
        "observation",
    ]
    assert [c.node_id for c in run.calls] == [0, 0, 1, 1, 1, 2, 2, 2, 2]
    assert run.client.requests[1].hints["role"] == "planner"
    assert run.nodes == [
        node(0, None, 0, 0, GOAL, "root", "open", [NodeVersion(0, SPLIT["think"], ("clear block A", "build the tower"), 1, 3)]),
        node(1, 0, 1, 0, "clear block A", "primitive", "done"),
        node(2, 0, 1, 1, "build the tower", "primitive", "open"),
    ]
    assert [(s.action, s.node_id) for s in run.steps] == list(zip(DEMO_ACTIONS, [1, 1, 2, 2, 2, 2]))


def test_and_stops_at_the_first_failed_subtask():
    run = run_agent(ADaPTAgent(ADaPTConfig(max_depth=2)), [FAILED, SPLIT, FAILED])
    assert (run.result.end_reason, run.result.error) == ("agent_done", "the goal failed at every depth")
    assert run.result.llm_calls == 3  # "build the tower" never runs; depth 2 is not decomposed
    assert run.nodes == [
        node(0, None, 0, 0, GOAL, "root", "failed", [NodeVersion(0, SPLIT["think"], ("clear block A", "build the tower"), 1, 3)]),
        node(1, 0, 1, 0, "clear block A", "primitive", "failed"),
    ]


def test_or_tries_alternatives_until_one_succeeds():
    options = {"think": "two ways", "subtasks": ["build it straight away", "build it step by step"], "logic": "or"}
    run = run_agent(ADaPTAgent(ADaPTConfig(max_depth=2)), [FAILED, options, FAILED, *REACT])
    assert run.result.end_reason == "success" and run.result.llm_calls == 9
    assert [(n.task, n.status) for n in run.nodes] == [
        (GOAL, "open"),
        ("build it straight away", "failed"),
        ("build it step by step", "open"),
    ]
    # the first success ends an OR: the second alternative is never tried
    run = run_agent(ADaPTAgent(ADaPTConfig(max_depth=2)), [FAILED, options, DONE])
    assert (run.result.end_reason, run.result.error) == (
        "agent_done",
        "the goal was reported done but the environment does not confirm it",
    )
    assert [(n.task, n.status) for n in run.nodes] == [(GOAL, "done"), ("build it straight away", "done")]


def test_or_fails_when_every_alternative_fails():
    options = {"think": "two ways", "subtasks": ["way one", "way two"], "logic": "or"}
    run = run_agent(ADaPTAgent(ADaPTConfig(max_depth=2)), [FAILED, options, FAILED, FAILED])
    assert run.result.end_reason == "agent_done" and run.result.llm_calls == 4
    assert [n.status for n in run.nodes] == ["failed", "failed", "failed"]


def test_recursion_stops_at_max_depth():
    deeper = {"think": "smaller", "subtasks": ["move C to the table", "never reached"], "logic": "and"}
    run = run_agent(ADaPTAgent(), [FAILED, SPLIT, FAILED, deeper, FAILED])
    assert run.result.end_reason == "agent_done" and run.result.max_depth == 2
    assert [c.purpose for c in run.calls] == ["executor_task", "planner_task", "executor_task", "planner_task", "executor_task"]
    assert [(n.node_id, n.parent_id, n.depth, n.task, n.kind, n.status) for n in run.nodes] == [
        (0, None, 0, GOAL, "root", "failed"),
        (1, 0, 1, "clear block A", "composite", "failed"),
        (2, 1, 2, "move C to the table", "primitive", "failed"),
    ]
    # max_depth 1: the executor alone, never the planner
    run = run_agent(ADaPTAgent(ADaPTConfig(max_depth=1)), [FAILED])
    assert (run.result.end_reason, run.result.llm_calls) == ("agent_done", 1)


def test_empty_decomposition_fails_the_task():
    run = run_agent(ADaPTAgent(), [FAILED, {"think": "no idea", "subtasks": [], "logic": "and"}])
    assert run.result.end_reason == "agent_done" and run.result.llm_calls == 2
    assert run.nodes[0].status == "failed"


# -- the executor's limits ------------------------------------------------------------------------------------


def test_executor_budget_counts_replies():
    run = run_agent(ADaPTAgent(ADaPTConfig(executor_steps=2, max_depth=1)), [REACT[0], REACT[1]])
    assert (run.result.end_reason, run.result.steps, run.result.llm_calls) == ("agent_done", 2, 2)
    # a failed run leaves the state where it is: the planner and next executor start from it
    run = run_agent(ADaPTAgent(ADaPTConfig(executor_steps=2)), [REACT[0], REACT[1], SPLIT, LLMError("auth", "stop")])
    assert run.seq()[3:5] == [(3, "assistant", "reply", False), (4, "user", "planner_task", True)]
    assert run.content(4) == planner_prompt(GOAL, OBS[2], last="put down C")


def test_invalid_action_feedback_and_patience_in_reject_mode():
    bad = {"think": "try", "action": "put down"}
    run = run_agent(ADaPTAgent(ADaPTConfig(executor_patience=2, max_depth=1)), [bad, REACT[0], bad, bad])
    assert run.result.end_reason == "agent_done" and run.result.llm_calls == 4
    assert [m.kind for m in run.messages] == [
        "executor_task",
        "reply",
        "feedback",
        "reply",
        "observation",
        "reply",
        "feedback",
        "reply",
    ]
    assert run.content(2) == (
        "Error feedback: 'put down' is not one of the valid actions, so it was not carried out and nothing "
        f"changed. Choose an action exactly as it is written among the valid actions.\n\nObservation:\n{OBS[0]}"
    )
    assert [(s.action, s.valid, s.env_step) for s in run.steps] == [
        ("put down", False, 0),
        ("unstack C from A", True, 1),
        ("put down", False, 1),
        ("put down", False, 1),
    ]


def test_invalid_action_reaches_the_environment_in_step_mode():
    bad = {"think": "try", "action": "put down"}
    run = run_agent(ADaPTAgent(ADaPTConfig(executor_patience=2, max_depth=1)), [bad, bad], env=stepping_env())
    assert run.result.end_reason == "agent_done" and run.result.steps == 2
    assert run.content(2) == "Observation:\nNothing happens."
    assert run.steps == [
        StepRecord("ep", 0, 1, "put down", False, "Nothing happens.", False, False, 0),
        StepRecord("ep", 1, 2, "put down", False, "Nothing happens.", False, False, 0),
    ]


def test_executor_and_planner_reply_shapes_are_repaired():
    both = {"think": "t", "action": "unstack C from A", "status": "done"}
    unknown = {"think": "t", "status": "maybe"}
    xor = {"think": "t", "subtasks": ["a"], "logic": "xor"}
    no_logic = {"think": "t", "subtasks": ["clear block A"]}
    run = run_agent(ADaPTAgent(ADaPTConfig(max_depth=2)), [both, unknown, FAILED, xor, no_logic, FAILED])
    repairs = [m.content.split("\n")[0] for m in run.messages if m.kind == "repair"]
    assert repairs == [
        'I could not use your last reply: give either an "action" or a "status", not both.',
        'I could not use your last reply: "status" must be "done" or "failed" (leave it out to take an action).',
        'I could not use your last reply: "logic" must be "and" or "or".',
    ]
    assert run.messages[2].content.endswith(
        'of the form {"think": "<your reasoning>", "action": "<one valid action>"} to act, or '
        '{"think": "<your reasoning>", "status": "done" or "failed"} to finish the task and nothing else.'
    )
    assert run.messages[8].content.endswith(
        'of the form {"think": "<your reasoning>", "subtasks": ["<subtask>", ...], "logic": "and" or "or"} and nothing else.'
    )
    # logic left out means "and"; the only subtask then fails at depth 2
    assert run.result.end_reason == "agent_done" and run.nodes[0].versions[0].subtasks == ("clear block A",)
    assert run.result.json_repairs == 3


def test_caps_and_errors_span_every_context():
    run = run_agent(ADaPTAgent(ADaPTConfig(max_llm_calls=3)), [FAILED, SPLIT, REACT[0], REACT[1]])
    assert (run.result.end_reason, run.result.llm_calls) == ("call_cap", 3)
    run = run_agent(ADaPTAgent(), [FAILED, LLMError("budget", "spent")])
    assert run.result.end_reason == "budget_exhausted"
    # context-length recovery inside a sub-executor drops only that context's oldest messages
    run = run_agent(
        ADaPTAgent(ADaPTConfig(max_depth=2)), [FAILED, SPLIT, REACT[0], LLMError("context_length", "long"), REACT[1], FAILED]
    )
    assert run.windows() == [(0,), (2,), (4,), (4, 5, 6), (4, 6), (4, 6, 7, 8)]
    assert [(c.call_index, c.status) for c in run.calls] == [(0, "ok"), (1, "ok"), (2, "ok"), (3, "error"), (4, "ok"), (5, "ok")]
    assert (run.result.end_reason, run.result.steps) == ("agent_done", 2)


def test_initial_observation_option_shows_the_first_observation_once_the_state_moved():
    cfg = ADaPTConfig(initial_observation=True, executor_steps=1)
    run = run_agent(ADaPTAgent(cfg), [REACT[0], SPLIT, LLMError("auth", "stop")])
    assert run.content(0) == executor_prompt(GOAL, OBS[0])
    assert run.content(2) == "\n\n".join(
        [
            PLANNER_SYSTEM,
            RULES_PART,
            f"Observation at the start of the episode:\n{OBS[0]}",
            "Last action taken in the environment: unstack C from A",
            f"Current observation:\n{OBS[1]}",
            f"Task to break down: {GOAL}",
            "Write the subtasks and how they combine.",
        ]
    )


# -- demonstrations -------------------------------------------------------------------------------------------


def test_demonstrations_are_pinned_in_every_context():
    env = BlocksworldEnv([["A", "C"], ["B"]], ["A", "B", "C"], instance_id="blocksworld/test")
    agent = ADaPTAgent()
    run = run_agent(agent, [FAILED, SPLIT, REACT[0], REACT[1], DONE, *REACT[2:]], env=env, demonstration=True)
    assert run.result.end_reason == "success"
    executor_demo = agent.render_demonstration(DEMONSTRATION)
    planner_demo = agent.render_planner_demonstration(DEMONSTRATION)
    pins = [(m.seq, m.kind) for m in run.messages if m.pinned]
    assert pins == [
        (0, "demonstration"),
        (1, "executor_task"),
        (3, "demonstration"),
        (4, "planner_task"),
        (6, "demonstration"),
        (7, "executor_task"),
        (13, "demonstration"),
        (14, "executor_task"),
    ]
    assert [run.content(s) for s in (0, 3, 6, 13)] == [executor_demo, planner_demo, executor_demo, executor_demo]
    assert run.windows()[:3] == [(0, 1), (3, 4), (6, 7)]
    # a demonstration given as text goes to every context as is
    run = run_agent(ADaPTAgent(ADaPTConfig(max_depth=2)), [FAILED, SPLIT, FAILED], demonstration="DEMO")
    assert [m.content for m in run.messages if m.kind == "demonstration"] == ["DEMO", "DEMO", "DEMO"]


def test_executor_demonstration_is_the_react_demo_in_executor_format():
    text = ADaPTAgent().render_demonstration(DEMONSTRATION)
    first_prompt = f"[Example prompt]\nCurrent observation:\n{OBS[0]}\n\nYour task: {GOAL}\n\n{EXEC_CLOSING}"
    assert (
        text.split("\n\n[Example reply]")[0]
        == "Here is a complete example of the interaction, from the first prompt to the goal being reached.\n\n" + first_prompt
    )
    assert [json.loads(block.split("\n", 1)[1]) for block in text.split("\n\n") if block.startswith("[Example reply]")] == REACT


def test_adapt_planner_entry_overrides_the_derived_planner_example():
    from recap.env import Demonstration

    custom = Demonstration(
        name="blocksworld/demo-adapt",
        make_env=DEMONSTRATION.make_env,
        replies={**DEMONSTRATION.replies, "adapt_planner": [{"think": "options", "subtasks": ["a", "b"], "logic": "or"}]},
    )
    text = ADaPTAgent().render_planner_demonstration(custom)
    assert '[Example reply]\n{"think": "options", "subtasks": ["a", "b"], "logic": "or"}' in text
    broken = Demonstration(
        name="blocksworld/demo-none", make_env=DEMONSTRATION.make_env, replies={"react": DEMONSTRATION.replies["react"]}
    )
    from recap.agent import DemonstrationError

    with pytest.raises(DemonstrationError, match="has no 'adapt_planner' or 'recap' replies"):
        ADaPTAgent().render_planner_demonstration(broken)


def test_window_trims_each_context_and_keeps_its_two_pins():
    run = run_agent(ADaPTAgent(ADaPTConfig(window=4)), [FAILED, SPLIT, *REACT], demonstration="DEMO")
    assert run.result.end_reason == "success" and run.result.llm_calls == 8
    assert [(m.seq, m.kind) for m in run.messages if m.pinned] == [
        (0, "demonstration"),
        (1, "executor_task"),
        (3, "demonstration"),
        (4, "planner_task"),
        (6, "demonstration"),
        (7, "executor_task"),
    ]
    assert run.windows() == [
        (0, 1),
        (3, 4),
        (6, 7),
        (6, 7, 8, 9),
        (6, 7, 8, 9, 10, 11),
        (6, 7, 10, 11, 12, 13),
        (6, 7, 12, 13, 14, 15),
        (6, 7, 14, 15, 16, 17),
    ]
