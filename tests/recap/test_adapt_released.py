"""ADaPT as released (``algorithm: plan_once``): one planner call, one ReAct executor per subtask,
the first OR branch, executors ended by Finish or by giving up, no success check, no re-planning;
the released profile choosing it; offline expert episodes on blocksworld and Robotouille."""

from __future__ import annotations

import pytest

from recap.baselines import ADaPTAgent, ADaPTConfig
from recap.baselines import text_prompts as T
from recap.blocksworld import DEMONSTRATION, RULES
from recap.config import ConfigError
from recap.methods import make_agent
from schemas.records import MessageRecord, NodeRecord
from tests.doubles.offline_expert_client import OfflineExpert
from tests.recap.baseline_harness import DEMO_ACTIONS, GOAL, demo_env, obs_after, run_agent
from workers.envs.registry import get_benchmark

RELEASED = {"algorithm": "plan_once", "json_mode": False, "planner_temperature": 0.0, "executor_window": 64}
OBS = [obs_after(*DEMO_ACTIONS[:i]) for i in range(len(DEMO_ACTIONS) + 1)]
CHUNKS = [
    "subgoal 1: unstack C from A; put down C",
    "subgoal 2: pick up B; stack B on A",
    "subgoal 3: pick up C; stack C on B",
]
PLANNER_SYSTEM = (
    "You are a planner. From the observation (the objects, the goal and the valid actions), split the goal "
    "into a short plan of two to four abstract subtasks for an executor that carries them out one by one. A "
    "subtask names the objects it concerns but is not itself one of the valid actions; do not repeat the "
    "observation.\n\nReply in plain text: your reasoning, then one line per subtask in the form 'Step <n>: "
    "<subtask>', then one final line 'Execution order: <expression>' that combines the steps with AND, OR and "
    "parentheses, for example 'Execution order: (Step 1 AND Step 2) AND Step 3'."
)


def agent(**kw) -> ADaPTAgent:
    return ADaPTAgent(ADaPTConfig(**{**RELEASED, **kw}))


def test_released_profile_is_the_released_adapt_except_on_alfworld():
    c = make_agent("adapt", "released", benchmark=get_benchmark("robotouille")).config
    assert (c.algorithm, c.json_mode, c.planner_temperature, c.executor_window, c.executor_patience) == (
        "plan_once",
        False,
        0.0,
        64,
        5,
    )
    assert make_agent("adapt", "released", benchmark=get_benchmark("alfworld")).config.algorithm == "as_needed"
    assert make_agent("adapt", "paper", benchmark=get_benchmark("robotouille")).config.algorithm == "as_needed"
    with pytest.raises(ConfigError, match=r"^algorithm: plan_once needs json_mode: false"):
        ADaPTConfig(algorithm="plan_once").validate()
    with pytest.raises(ConfigError, match=r'^planner_temperature must be in \[0, 2\], null or "same", got 3$'):
        ADaPTConfig(planner_temperature=3).validate()


def test_offline_expert_episode_plans_once_and_runs_one_executor_per_subtask():
    env = demo_env()
    client = OfflineExpert(env)
    records: list = []
    result = agent().run(env, client, episode_id="ep", emit=records.append, demonstration=False)
    assert (result.end_reason, result.steps, result.llm_calls, result.max_depth) == ("success", 6, 9, 1)
    msgs = [m for m in records if isinstance(m, MessageRecord)]
    kinds = [(m.seq, m.role, m.kind, m.pinned) for m in msgs]
    exec_run = [("user", "executor_task", True), ("assistant", "reply", False)]
    step = [("user", "observation", False), ("assistant", "reply", False)]
    shape = [("user", "planner_task", True), ("assistant", "reply", False)]
    shape += exec_run + step + step + exec_run + step + step + exec_run + step
    assert kinds == [(i, *k) for i, k in enumerate(shape)]
    text = {m.seq: m.content for m in msgs}
    assert text[0] == f"{PLANNER_SYSTEM}\n\nRules of the environment:\n{RULES}\n\nObservation:\n{OBS[0]}\n\nGoal: {GOAL}"
    assert text[1] == (
        "Expert plan: 6 action(s) left.\n\nPlan:\n"
        + "\n".join(f"Step {i}: {c}" for i, c in enumerate(CHUNKS, 1))
        + "\nExecution order: Step 1 AND Step 2 AND Step 3"
    )
    assert text[2] == (
        f"{T.executor_system()}\n\nRules of the environment:\n{RULES}\n\n"
        f"Observation:\n{OBS[0]}\n\nGoal: {GOAL}\n\nSubtask: {CHUNKS[0]}"
    )
    assert text[3] == "Reasoning: Expert plan: 6 action(s) left.\n\nAction: unstack C from A"
    assert text[4] == f"Observation:\n{OBS[1]}\n\nSubtask: {CHUNKS[0]}"
    assert text[7] == "Reasoning: Expert plan: 4 action(s) left.\n\nAction: Finish"
    assert text[8].endswith(f"Observation:\n{OBS[2]}\n\nGoal: {GOAL}\n\nSubtask: {CHUNKS[1]}")
    # one planner call at the planner temperature; executors at the agent's
    assert [(r.purpose, r.temperature) for r in client.requests][:2] == [("planner_task", 0.0), ("executor_task", 0.5)]
    assert [r.purpose for r in client.requests].count("planner_task") == 1
    nodes = [(n.node_id, n.parent_id, n.task, n.kind, n.status) for n in records if isinstance(n, NodeRecord)]
    assert nodes == [
        (0, None, GOAL, "root", "open"),
        (1, 0, CHUNKS[0], "executor_task", "done"),
        (2, 0, CHUNKS[1], "executor_task", "done"),
        (3, 0, CHUNKS[2], "executor_task", "open"),
    ]


PLAN_OR = "why\nStep 1: clear block A\nStep 2: never run\nStep 3: build the tower\nExecution order: (Step 1 OR Step 2) AND Step 3"


def test_the_first_or_branch_runs_and_a_finished_plan_ends_the_episode():
    replies = [
        PLAN_OR,
        "Reasoning: C off A\nAction: Unstack C from A.",
        "Reasoning: put it down\nAction: put down C",
        "Reasoning: A is clear\nAction: Finish",
        "Reasoning: wrong idea\nAction: Finish",
    ]
    run = run_agent(agent(), replies)
    assert (run.result.end_reason, run.result.steps, run.result.llm_calls) == ("agent_done", 2, 5)
    assert run.result.error == "the plan's 2 subtask(s) ran without reaching the goal"
    assert [(n.task, n.status) for n in run.nodes] == [
        (GOAL, "failed"),
        ("clear block A", "done"),
        ("build the tower", "done"),
    ]
    assert run.nodes[0].versions[0].subtasks == ("clear block A", "build the tower")
    assert [s.action for s in run.steps] == ["unstack C from A", "put down C"]


def test_an_executor_that_gives_up_hands_over_to_the_next_subtask_without_rollback_or_replanning():
    bad = ["Reasoning: x\nAction: fly", "no action here"] * 2 + ["Reasoning: x\nAction: fly"]
    replies = [PLAN_OR, "Reasoning: C off A\nAction: unstack C from A", *bad, "Reasoning: done\nAction: Finish"]
    run = run_agent(agent(), replies)
    assert (run.result.end_reason, run.result.steps, run.result.llm_calls, run.result.invalid_actions) == (
        "agent_done",
        1,
        8,
        3,
    )
    assert [(n.task, n.status) for n in run.nodes][1:] == [("clear block A", "failed"), ("build the tower", "done")]
    users = [m for m in run.messages if m.role == "user"]
    assert [m.kind for m in users] == [
        "planner_task",
        "executor_task",
        "observation",
        "feedback",
        "feedback",
        "feedback",
        "feedback",
        "executor_task",
    ]
    assert users[3].content == (
        "Error feedback: 'fly' does not match any of the valid actions. Choose one of the valid actions.\n\n"
        f"Observation:\n{OBS[1]}\n\nSubtask: clear block A"
    )
    assert users[4].content.startswith("Error feedback: Your reply has no reasoning.")
    # the next executor starts where the failed one left the world (C still held)
    assert users[7].content.endswith(f"\n\nObservation:\n{OBS[1]}\n\nGoal: {GOAL}\n\nSubtask: build the tower")


def test_a_plan_without_steps_ends_the_episode():
    run = run_agent(agent(), ["1. clear A\n2. build"])
    assert (run.result.end_reason, run.result.error, run.result.llm_calls) == (
        "agent_done",
        "the planner's reply lists no step",
        1,
    )


def test_demonstrations_are_our_script_in_the_released_layouts():
    a = agent()
    executor = a.render_demonstration(DEMONSTRATION)
    planner = a.render_planner_demonstration(DEMONSTRATION)
    assert executor.count("[Example reply]\nReasoning: ") == len(DEMO_ACTIONS)
    assert f"[Example prompt]\nObservation:\n{OBS[0]}\n\nGoal: {GOAL}\n\nSubtask: {GOAL}\n\n" in executor
    assert planner.startswith(f"Here is an example of a goal split into subtasks.\n\n[Example prompt]\nObservation:\n{OBS[0]}")
    assert planner.endswith("\nExecution order: Step 1 AND Step 2\n\n[End of example.]")


def test_robotouille_offline_expert_episode():
    from workers.envs.registry import make_env

    env = make_env("robotouille/synchronous/0_cheese_sandwich@42")
    client = OfflineExpert(env)
    records: list = []
    result = make_agent("adapt", "released", benchmark=get_benchmark("robotouille")).run(
        env, client, episode_id="ep", emit=records.append
    )
    assert result.end_reason == "success"
    purposes = [r.purpose for r in client.requests]
    assert purposes.count("planner_task") == 1 and purposes[0] == "planner_task"
    msgs = [m for m in records if isinstance(m, MessageRecord)]
    # the episode's demonstration, then the planner's context (its example, its prompt, the plan)
    assert [m.kind for m in msgs[:4]] == ["demonstration", "demonstration", "planner_task", "reply"]
    assert msgs[2].content.endswith(f"\n\nGoal: {env.reset().goal}")
    plan = [n for n in records if isinstance(n, NodeRecord)][0].versions[0].subtasks
    executor_prompts = [m.content for m in msgs if m.kind == "executor_task"]
    assert len(executor_prompts) >= 1
    assert [p.rsplit("\n\nSubtask: ", 1)[1] for p in executor_prompts] == list(plan[: len(executor_prompts)])
    assert result.steps == len([s for s in records if type(s).__name__ == "StepRecord" and s.valid])


def test_an_executor_trims_its_history_by_pairs_but_keeps_its_first_reply():
    # the release's executor is a ReActAgent: ``del truncated_history[2:4]`` once past its bound
    # keeps the first prompt (our pin) and the first reply (ReAct_agent.py:129-130)
    plan = "why\nStep 1: build the tower\nExecution order: Step 1"
    replies = [plan, *(f"Reasoning: step {i}\nAction: {a}" for i, a in enumerate(DEMO_ACTIONS))]
    run = run_agent(agent(executor_window=4), replies)
    assert (run.result.end_reason, run.result.steps) == ("success", 6)
    assert run.windows() == [(0,), (2,), (2, 3, 4), (2, 3, 4, 5, 6), (2, 3, 6, 7, 8), (2, 3, 8, 9, 10), (2, 3, 10, 11, 12)]
    assert run.content(3) == f"Reasoning: step 0\nAction: {DEMO_ACTIONS[0]}"
