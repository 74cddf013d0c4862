"""ADaPT on a partially observed environment: every executor's task prompt shows the episode's
first observation once the state has moved on; on a fully observed one nothing changes."""

from __future__ import annotations

from recap.baselines import ADaPTAgent, ADaPTConfig
from recap.blocksworld import BlocksworldEnv
from recap.env import Environment
from recap.llm import LLMError
from tests.recap.baseline_harness import SteppingBlocksworld, run_agent
from tests.recap.test_baseline_adapt import (
    DONE,
    EXEC_CLOSING,
    EXECUTOR_SYSTEM,
    FAILED,
    GOAL,
    OBS,
    REACT,
    RULES_PART,
    SPLIT,
    executor_prompt,
    planner_prompt,
)
from workers.envs.alfworld.replay import ReplayEnvironment


class PartialBlocksworld(BlocksworldEnv):
    """The blocksworld of the baseline tests, declared partially observed."""

    partially_observed = True


class PartialStepping(SteppingBlocksworld):
    partially_observed = True


def partial_env() -> PartialBlocksworld:
    return PartialBlocksworld([["A", "C"], ["B"]], ["A", "B", "C"], instance_id="blocksworld/partial", demo=False)


def executor_prompt_with_start(task: str, obs: str, last: str) -> str:
    return "\n\n".join(
        [
            EXECUTOR_SYSTEM,
            RULES_PART,
            f"Observation at the start of the episode:\n{OBS[0]}",
            f"Last action taken in the environment: {last}",
            f"Current observation:\n{obs}",
            f"Your task: {task}",
            EXEC_CLOSING,
        ]
    )


def test_the_interface_default_and_the_benchmarks():
    assert Environment.partially_observed is False
    assert BlocksworldEnv.partially_observed is False
    assert ReplayEnvironment.partially_observed is True
    from workers.envs.alfworld.game_env import AlfworldEnvironment
    from workers.envs.robotouille.env import RobotouilleEnv

    assert AlfworldEnvironment.partially_observed is True
    assert RobotouilleEnv.partially_observed is False


def test_every_executor_on_a_partially_observed_env_gets_the_initial_observation():
    script = [FAILED, SPLIT, REACT[0], REACT[1], DONE, *REACT[2:]]
    run = run_agent(ADaPTAgent(), script, env=partial_env())
    assert run.result.end_reason == "success"
    # before any action the current observation is the initial one: shown once
    assert run.content(0) == executor_prompt(GOAL, OBS[0])
    assert run.content(4) == executor_prompt("clear block A", OBS[0])
    # the planner is unchanged (the initial_observation option governs it)
    assert run.content(2) == planner_prompt(GOAL, OBS[0])
    # an executor opened after the state moved on sees the start of the episode
    assert run.content(10) == executor_prompt_with_start("build the tower", OBS[2], last="put down C")


def test_a_planner_after_a_failed_executor_and_the_next_executor():
    script = [REACT[0], REACT[1], SPLIT, LLMError("auth", "stop")]
    run = run_agent(ADaPTAgent(ADaPTConfig(executor_steps=2)), script, env=partial_env())
    assert run.content(4) == planner_prompt(GOAL, OBS[2], last="put down C")
    assert run.content(6) == executor_prompt_with_start("clear block A", OBS[2], last="put down C")


def test_nothing_happens_in_step_mode_still_shows_the_start():
    bad = {"think": "try", "action": "put down"}
    env = PartialStepping([["A", "C"], ["B"]], ["A", "B", "C"], instance_id="blocksworld/partial-step", demo=False)
    run = run_agent(ADaPTAgent(ADaPTConfig(executor_steps=1)), [bad, SPLIT, LLMError("auth", "stop")], env=env)
    assert run.content(4) == executor_prompt_with_start("clear block A", "Nothing happens.", last="put down")


def test_a_fully_observed_env_is_unchanged():
    script = [FAILED, SPLIT, REACT[0], REACT[1], DONE, *REACT[2:]]
    run = run_agent(ADaPTAgent(), script)
    assert run.result.end_reason == "success"
    assert run.content(4) == executor_prompt("clear block A", OBS[0])
    assert run.content(10) == executor_prompt("build the tower", OBS[2], last="put down C")
    assert "Observation at the start of the episode" not in "".join(m.content for m in run.messages)
