"""ReAct and Act on a Robotouille kitchen under the ``paper`` and ``released`` profiles (issue 25,
item 2): the benchmark's "original" ReAct keeps the whole history until it passes 64 messages,
then drops the oldest (observation, reply) pair after the first exchange
(robotouille-baselines/agents/ReAct_agent.py:129-130); the released Act keeps everything
(Act_agent.py:129-131 commented out). Baselines sample at 0.7 as released, 0.5 in the paper.
``paper`` replies in our JSON, ``released`` in the release's plain-text lines (item 8); the
history rules are the same in both loops."""

from __future__ import annotations

import pytest

from recap.baselines import text_prompts as T
from recap.llm import LLMError
from recap.methods import make_agent
from recap.scripted import ScriptedClient
from tests.workers.envs.robotouille.helpers import require_data
from workers.envs.registry import get_benchmark, make_env

TASK6 = "robotouille/synchronous/6_lettuce_tomato_cheeseburger@42"
THERE, BACK = "Move robot1 from table1 to table2", "Move robot1 from table2 to table1"
#: valid moves back and forth: the kitchen never reaches the goal
MOVES = 40
STOP = LLMError("server_error", "end of the script")


def _reply(method: str, profile: str, think: str, action: str) -> object:
    """One reply as the profile's reply format writes it: JSON (paper), text lines (released)."""
    if profile == "released":
        return f"Reasoning: {think}\nAction: {action}" if method == "react" else f"Action: {action}"
    return {"think": think, "action": action} if method == "react" else {"action": action}


def _run(method: str, profile: str):
    agent = make_agent(method, profile=profile, benchmark=get_benchmark("robotouille"))
    env = make_env(TASK6, data_dir=str(require_data()), step_multiplier=3)
    replies: list = []
    for i in range(MOVES):
        action = THERE if i % 2 == 0 else BACK
        replies.append(_reply(method, profile, f"step {i}", action))
    client = ScriptedClient([*replies, STOP])
    result = agent.run(env, client, episode_id="ep", demonstration="DEMO")
    return agent, env, result, client


@pytest.mark.parametrize("profile", ["paper", "released"])
def test_react_keeps_64_messages_then_trims_the_oldest_pair_after_the_first_reply(profile):
    agent, env, result, client = _run("react", profile)
    assert (result.end_reason, result.steps, result.llm_calls) == ("llm_error", MOVES, MOVES + 1)
    first = client.requests[0].messages
    assert [m.content for m in first][0] == "DEMO"
    if profile == "paper":
        assert first[1].content.startswith("You are an agent that reaches a goal in an environment one action at a time.")
        assert first[1].content.endswith(
            "\n\nYour goal:\nPrepare a lettuce tomato cheeseburger on a table\n\nReply with your first action."
        )
    else:  # the observation, which states the goal, stated once (ReAct_agent.py:232-235)
        assert first[1].content.startswith(T.react_system(True) + "\n\nRules of the environment:\n")
        assert first[1].content.endswith("\n\nGoal: Prepare a lettuce tomato cheeseburger on a table")
        assert first[1].content.count("Goal: ") == 1
    # later prompts: the new observation (the whole kitchen with its valid actions)
    later = client.requests[1].messages[-1].content
    assert later.startswith("Observation:\n") and "Move robot1 from table2 to table1" in later
    for c, request in enumerate(client.requests):
        if c <= 32:  # the whole history: pins + 2c messages
            assert request.window_seqs == tuple(range(2 + 2 * c)), c
        else:  # 64 after the pins: the first reply (seq 2) and the newest 63
            assert request.window_seqs == (0, 1, 2, *range(2 * c - 61, 2 * c + 2)), c
            assert len(request.messages) == 2 + 64
    assert client.requests[-1].messages[2].content == (
        '{"think": "step 0", "action": "Move robot1 from table1 to table2"}'
        if profile == "paper"
        else "Reasoning: step 0\nAction: Move robot1 from table1 to table2"
    )
    assert {r.temperature for r in client.requests} == {0.5 if profile == "paper" else 0.7}
    assert {r.max_tokens for r in client.requests} == {None}


@pytest.mark.parametrize("profile", ["paper", "released"])
def test_act_keeps_its_whole_history(profile):
    agent, env, result, client = _run("act", profile)
    assert (result.end_reason, result.steps) == ("llm_error", MOVES)
    assert [r.window_seqs for r in client.requests] == [tuple(range(2 + 2 * c)) for c in range(MOVES + 1)]
    assert len(client.requests[-1].messages) == 2 + 2 * MOVES  # past 64: nothing trimmed
    assert {r.temperature for r in client.requests} == {0.5 if profile == "paper" else 0.7}


@pytest.mark.parametrize("profile", ["paper", "released"])
def test_invalid_actions_still_end_after_three_rounds_of_five(profile):
    agent = make_agent("react", profile=profile, benchmark=get_benchmark("robotouille"))
    env = make_env(TASK6, data_dir=str(require_data()), step_multiplier=3)
    client = ScriptedClient([_reply("react", profile, "t", "fly away")] * 15)
    result = agent.run(env, client, episode_id="ep", demonstration="DEMO")
    what = "invalid actions" if profile == "paper" else "unusable replies"
    assert (result.end_reason, result.error, result.invalid_actions) == (
        "agent_done",
        f"3 rounds of 5 consecutive {what}",
        15,
    )
    feedback = (
        "Error feedback: 'fly away' is not one of the valid actions, so it was not carried out and nothing changed."
        if profile == "paper"
        else "Error feedback: 'fly away' does not match any of the valid actions. Choose one of the valid actions."
    )
    assert client.requests[1].messages[-1].content.startswith(feedback)
