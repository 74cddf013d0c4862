"""ReAct and Act on a real ALFWorld game under the ``paper`` and ``released`` profiles (issue 25,
item 1): the exact first and later prompts - the valid actions after the first observation and
after every valid command, none in the demonstration, the explained feedback after an invalid
command, "OK." after a thought (no step used) - and ``profile: none`` unchanged. ``paper`` runs
ReAct with our JSON replies, ``released`` with the release's one-line text (item 8); the two loops
send the same observations and feedback."""

from __future__ import annotations

import dataclasses
import json

import pytest

from recap.baselines import text_prompts as T
from recap.llm import LLMError
from recap.methods import make_agent
from recap.scripted import ScriptedClient
from tests.workers.envs.alfworld.helpers import DATA, HEAT_ID, HEAT_START
from tests.workers.envs.alfworld.test_alfworld_valid_actions import ARRIVE_LIST, HEAT_ARRIVE, START_LIST
from workers.envs.alfworld import AlfworldBenchmark
from workers.envs.alfworld.demos import demonstration_for
from workers.envs.alfworld.rules import rules_text
from workers.envs.registry import get_benchmark
from workers.episode_worker import env_options_for

#: ends a scripted episode after the prompts under test
STOP = LLMError("server_error", "end of the script")
GOAL = "heat some apple and put it in fridge"
REACT_SYSTEM = (
    "You are an agent that reaches a goal in an environment one action at a time. At every turn you think about "
    "the latest observation, then choose exactly one action; I carry it out and show you what happened. An action "
    "that is not one of the valid actions is not carried out, and I tell you so.\n\n"
    "Answer every time with one JSON object and nothing else:\n"
    '{"think": "<your reasoning>", "action": "<one valid action>"}\n'
    '- "think": your reasoning before acting: what the goal still needs, what the latest observation and your '
    "earlier steps tell you, and why the action you choose moves you towards the goal. If your last action was "
    "rejected, first work out why it was not valid.\n"
    '- "action": the single next action, written exactly as it appears among the valid actions.\n'
    'To think without acting, write the action as "think: <your thought>"; I answer "OK." and no step is used.'
)
ACT_SYSTEM = (
    "You are an agent that reaches a goal in an environment one action at a time. At every turn you choose "
    "exactly one action; I carry it out and show you what happened. An action that is not one of the valid "
    "actions is not carried out, and I tell you so.\n\n"
    "Answer every time with one JSON object and nothing else:\n"
    '{"action": "<one valid action>"}\n'
    '- "action": the single next action, written exactly as it appears among the valid actions.\n'
    'To think without acting, reply {"think": "<your thought>"} with no "action"; I answer "OK." and no step is used.'
)


def feedback(action: str, thought_hint: str, observation: str) -> str:
    return (
        f"'{action}' is not one of the valid actions, so it changed nothing. Likely causes:\n"
        "1. The command is not an exact copy of a valid action: copy it word for word, numbers included.\n"
        f"2. You meant to think rather than act: to think, {thought_hint}.\n"
        "3. Something you assumed about the situation does not hold: check the latest observation.\n\n"
        f"Observation:\n{observation}"
    )


@pytest.fixture(scope="module")
def bench() -> AlfworldBenchmark:
    return AlfworldBenchmark(DATA)


def _run(bench, method, profile, replies):
    """One episode of ``method`` under ``profile`` on the heat game, made the way a worker makes it."""
    agent = make_agent(method, profile=profile, benchmark=get_benchmark("alfworld"))
    work = type("W", (), {"benchmark": "alfworld", "env_options": ()})()
    options = env_options_for(work, agent)  # type: ignore[arg-type]
    env = bench.make(HEAT_ID, **options)
    client = ScriptedClient(replies)
    try:
        result = agent.run(env, client, episode_id="ep", demonstration=True)
    finally:
        env.close()
    return agent, options, result, client


def _task_prompt(system: str, rules: str) -> str:
    return (
        f"{system}\n\nRules of the environment:\n{rules}\n\n"
        f"Initial observation:\n{HEAT_START}{START_LIST}\n\nYour goal:\n{GOAL}\n\nReply with your first action."
    )


@pytest.mark.parametrize("method", ["react", "act"])
def test_paper_and_released_differ_only_in_temperature_and_reacts_reply_format(method):
    """The paper states no baseline protocol beyond T = 0.5, so ``paper`` runs the released one,
    with our JSON replies; ``released`` has ReAct reply in Yao et al.'s one line as react.py does
    (Act's act.py asks for JSON too)."""
    paper = make_agent(method, profile="paper", benchmark=get_benchmark("alfworld")).config
    released = make_agent(method, profile="released", benchmark=get_benchmark("alfworld")).config
    assert (paper.temperature, released.temperature) == (0.5, None)
    text = {"reply_format": "text", "json_mode": False, "text_layout": "yao"} if method == "react" else {}
    if method == "act":  # the released Act sends a malformed reply to the game (act.py:181-199)
        text = {"malformed_json": "game"}
    assert dataclasses.replace(paper, temperature=None, **text) == released


@pytest.mark.parametrize("profile", ["paper", "released"])
def test_react_sees_valid_actions_feedback_and_ok(bench, profile):
    if profile == "paper":
        replies: list = [
            {"think": "Where is an apple?", "action": "think: an apple is likely in the garbagecan"},
            {"think": "Take it.", "action": "take apple 2 from garbagecan 1"},
            {"think": "Go there first.", "action": "go to garbagecan 1"},
        ]
    else:
        replies = ["think: an apple is likely in the garbagecan", "take apple 2 from garbagecan 1", "go to garbagecan 1"]
    agent, options, result, client = _run(bench, "react", profile, replies + [STOP])
    assert options == {"show_valid_actions": True, "demo_valid_actions": False}
    first = client.requests[0].messages
    # pins: the demonstration (Yao et al.'s way: no valid-action lists) and the task prompt
    assert len(first) == 2 and "Valid actions:" not in first[0].content
    rules = rules_text("2.1.1", 50)
    if profile == "paper":
        assert first[1].content == _task_prompt(REACT_SYSTEM, rules)
    else:  # the first observation with its list, as released (react.py:209); it states the goal
        assert first[1].content == f"{T.yao_system()}\n\nRules of the environment:\n{rules}\n\n{HEAT_START}{START_LIST}"
    arrive = f"{HEAT_ARRIVE}{ARRIVE_LIST}"
    later = [r.messages[-1].content for r in client.requests[1:]]
    assert later == [
        "OK.",
        feedback(
            "take apple 2 from garbagecan 1", 'write the action as "think: <your thought>"', "Nothing happens." + START_LIST
        ),
        f"Observation:\n{arrive}" if profile == "paper" else arrive,
    ]
    # the thought used no step: 2 commands reached the game
    assert (result.steps, result.invalid_actions, result.llm_calls) == (2, 1, 4)
    assert [r.purpose for r in client.requests] == ["task", "thought", "feedback", "observation"]
    assert {r.json_mode for r in client.requests} == {profile == "paper"}


def test_act_sees_valid_actions_feedback_and_ok(bench):
    replies = [
        {"think": "an apple is likely in the garbagecan"},
        {"action": "take apple 2 from garbagecan 1"},
        {"action": "go to garbagecan 1"},
        # the released Act answers "OK." to any reply holding a think, even one that acted
        {"think": "take it now", "action": "take apple 2 from garbagecan 1"},
    ]
    agent, options, result, client = _run(bench, "act", "released", replies + [STOP])
    assert options == {"show_valid_actions": True, "demo_valid_actions": False}
    first = client.requests[0].messages
    assert len(first) == 2 and "Valid actions:" not in first[0].content
    assert first[1].content == _task_prompt(ACT_SYSTEM, rules_text("2.1.1", 50))
    later = [r.messages[-1].content for r in client.requests[1:]]
    assert later == [
        "OK.",
        feedback(
            "take apple 2 from garbagecan 1",
            'reply {"think": "<your thought>"} with no "action"',
            "Nothing happens." + START_LIST,
        ),
        f"Observation:\n{HEAT_ARRIVE}{ARRIVE_LIST}",
        "OK.",
    ]
    assert (result.steps, result.invalid_actions) == (3, 1)
    # no window: every call sees the whole history
    assert [len(r.messages) for r in client.requests] == [2, 4, 6, 8, 10]
    assert json.loads(client.requests[4].messages[2].content) == {"think": "an apple is likely in the garbagecan"}


def test_released_act_sends_a_malformed_reply_to_the_game(bench):
    """act.py:181-199, 221: text that is not JSON is the command "json parse error" (the game
    answers it and counts a step; the next message says the reply was not JSON), an empty action
    is the command "error", an object with neither field repeats the last message. No repair."""
    replies = ["```json\n{not json", {"action": ""}, {"foo": 1}, '```json\n{"action": "go to garbagecan 1"}\n```']
    agent, options, result, client = _run(bench, "act", "released", replies + [STOP])
    later = [(r.purpose, r.messages[-1].content) for r in client.requests[1:]]
    explained = feedback("error", 'reply {"think": "<your thought>"} with no "action"', "Nothing happens." + START_LIST)
    assert later == [
        ("feedback", "Your reply was not a valid JSON object. Reply with one JSON object that has an 'action' field."),
        ("feedback", explained),
        ("feedback", explained),
        ("observation", f"Observation:\n{HEAT_ARRIVE}{ARRIVE_LIST}"),
    ]
    assert (result.steps, result.invalid_actions, result.json_repairs) == (3, 2, 0)
    assert [len(r.messages) for r in client.requests] == [2, 4, 6, 8, 10]
    with pytest.raises(ValueError, match="^malformed_json must be repair or game, got 'x'$"):
        make_agent("act", malformed_json="x")


def test_without_a_profile_react_is_unchanged(bench):
    """``profile: none``: no lists, a thought is a command the game answers, no explained feedback."""
    replies = [
        {"think": "Where is an apple?", "action": "think: an apple is likely in the garbagecan"},
        {"think": "Go there.", "action": "go to garbagecan 1"},
    ]
    agent, options, result, client = _run(bench, "react", None, replies + [STOP])
    assert options == {"show_valid_actions": False}
    assert "Valid actions:" not in client.requests[0].messages[1].content
    assert [r.messages[-1].content for r in client.requests[1:]] == [
        "Observation:\nNothing happens.",
        f"Observation:\n{HEAT_ARRIVE}",
    ]
    assert (result.steps, result.invalid_actions) == (2, 1)


@pytest.mark.parametrize("profile", ["paper", "released"])
def test_explained_feedback_lists_the_valid_actions_when_the_observation_does_not(profile):
    """With the lists switched off by a setting, the feedback still carries them (as released);
    the demonstration's replay of the cool game stands in for a game here (same rules, fast)."""
    agent = make_agent("react", profile=profile, benchmark=get_benchmark("alfworld"), valid_actions="hidden")
    work = type("W", (), {"benchmark": "alfworld", "env_options": ()})()
    assert env_options_for(work, agent) == {"show_valid_actions": False}  # type: ignore[arg-type]
    env = demonstration_for("cool", show_valid_actions=False).make_env()
    start = env.reset()
    reply = {"think": "t", "action": "open the fridge"} if profile == "paper" else "open the fridge"
    client = ScriptedClient([reply, STOP])
    agent.run(env, client, episode_id="ep", demonstration=False)
    assert client.requests[1].messages[-1].content == feedback(
        "open the fridge", 'write the action as "think: <your thought>"', "Nothing happens."
    ) + "\n\nValid actions:\n" + "\n".join(start.valid_actions)


def test_valid_actions_setting_maps_to_the_game_options(bench):
    for choice, want in (
        ("shown", {"show_valid_actions": True}),
        ("episode", {"show_valid_actions": True, "demo_valid_actions": False}),
        ("hidden", {"show_valid_actions": False}),
    ):
        assert bench.options_for_agent("react", make_agent("react", valid_actions=choice).config) == want
    # no setting: the per-style choice (ReCAP sees them, the others do not)
    assert bench.options_for_agent("recap", make_agent("recap").config) == {"show_valid_actions": True}
    assert bench.options_for_agent("cot", make_agent("cot", profile="released", benchmark=get_benchmark("alfworld")).config) == {
        "show_valid_actions": False
    }
    with pytest.raises(ValueError, match=r"^demo_valid_actions must be true, false or null \(None\), got 'no'$"):
        bench.make(HEAT_ID, demo_valid_actions="no")


def test_react_release_prompts_send_the_released_first_messages(bench, tmp_path):
    """``prompts: release`` (issue 25 item 7): react.py:206-209 sends the task's example transcript
    after a sentence as one user message, then the first prompt (react.py:132-142: the stated
    rule, the task heading, the first observation with its valid actions); no system text or rules
    of ours. The release folder is a fixture in the released layout, in our own words."""
    from recap.baselines.text_prompts import RELEASE_ALFWORLD_RULE
    from workers.release.texts import release_prompt

    transcript = "Fixture household, task: warm a fixture.\n> think: fixture thought\nOK.\n> go to fixture 1\nDone.\n"
    demo = tmp_path / "alfworld-recap/react_alfworld/alfworld_3prompts_fixed.json"
    demo.parent.mkdir(parents=True)
    demo.write_text(json.dumps({"react_heat_0": transcript, "react_put_0": "another task's example"}))
    release = release_prompt(tmp_path, "react", "alfworld", "valid_seen", "heat")
    assert release is not None
    assert release.messages == (("user", f"Complete a task by interacting with a household. One example follows.\n{transcript}"),)
    agent = make_agent("react", profile="released", benchmark=get_benchmark("alfworld"), prompts="release")
    work = type("W", (), {"benchmark": "alfworld", "env_options": ()})()
    env = bench.make(HEAT_ID, **env_options_for(work, agent))  # type: ignore[arg-type]
    client = ScriptedClient(["think: the apple may be in the garbagecan", "go to garbagecan 1", STOP])
    try:
        agent.run(env, client, episode_id="ep", demonstration=release)
    finally:
        env.close()
    first = [(m.role, m.content) for m in client.requests[0].messages]
    assert first == [
        release.messages[0],
        (
            "user",
            f"\n        \nThe environment's rule:\n{RELEASE_ALFWORLD_RULE}\n\nThe task follows.\n\n{HEAT_START}{START_LIST}\n",
        ),
    ]
    later = [r.messages[-1].content for r in client.requests[1:]]
    assert later == ["OK.", f"{HEAT_ARRIVE}{ARRIVE_LIST}"]
    assert {r.json_mode for r in client.requests} == {False}


def test_act_release_prompts_send_the_released_first_messages(bench, tmp_path):
    """``prompts: release`` for Act (issue 25 item 7): act.py:297-304 re-reads the task's example
    (parse_fewshot, act.py:255-281: a ``think:`` reply and the user lines after it drop out, each
    command becomes ``{"action": ...}``) and sends it after a sentence as one user message, then
    the first prompt with its JSON request (act.py:158-172); later observations come as the game
    gives them (act.py:211). The fixture is in the released layout, in our own words."""
    from workers.release.texts import ALFWORLD_ACT_HEADER, release_prompt

    transcript = (
        "user: Fixture room with a fixture 1.\nYour task is to: warm a fixture.\n"
        "assistant: think: first find the fixture.\nuser: OK.\n"
        "assistant: go to fixture 1\nuser: You reach fixture 1.\nIt is cold.\n"
        "assistant: think: now warm it.\nuser: OK.\nuser: a second user line after the thought\n"
        "assistant: warm fixture 1\nuser: Done.\n"
    )
    demo = tmp_path / "alfworld-recap/act_alfworld/alfworld_3prompts_act.json"
    demo.parent.mkdir(parents=True)
    demo.write_text(json.dumps({"react_heat_0": transcript, "react_put_0": "another task's example"}))
    release = release_prompt(tmp_path, "act", "alfworld", "valid_seen", "heat")
    assert release is not None
    example = (
        "user: Fixture room with a fixture 1.\nYour task is to: warm a fixture.\n"
        'assistant: {"action": "go to fixture 1"}\nuser: You reach fixture 1.\nIt is cold.\n'
        'assistant: {"action": "warm fixture 1"}\nuser: Done.'
    )
    assert release.messages == (("user", ALFWORLD_ACT_HEADER + example),)
    agent = make_agent("act", profile="released", benchmark=get_benchmark("alfworld"), prompts="release")
    assert (agent.config.reply_format, agent.config.json_mode) == ("json", True)
    work = type("W", (), {"benchmark": "alfworld", "env_options": ()})()
    env = bench.make(HEAT_ID, **env_options_for(work, agent))  # type: ignore[arg-type]
    replies = [{"think": "the apple may be in the garbagecan"}, {"action": "go to garbagecan 1"}, STOP]
    client = ScriptedClient(replies)
    try:
        agent.run(env, client, episode_id="ep", demonstration=release)
    finally:
        env.close()
    first = [(m.role, m.content) for m in client.requests[0].messages]
    assert first == [
        release.messages[0],
        (
            "user",
            f"\n        \nThe environment's rule:\n{T.RELEASE_ALFWORLD_RULE}\n\n"
            "Answer with a JSON object holding an 'action' field, for instance:\n\n"
            '{"action": "open the drawer"}\n\n'
            f"The task follows.\n\n{HEAT_START}{START_LIST}\n",
        ),
    ]
    later = [r.messages[-1].content for r in client.requests[1:]]
    assert later == ["OK.", f"{HEAT_ARRIVE}{ARRIVE_LIST}"]
    assert {r.json_mode for r in client.requests} == {True}


def test_recap_release_prompts_send_the_released_first_messages(bench, tmp_path):
    """``prompts: release`` for ReCAP on ALFWorld (issue 25 item 7): the task's example joined one
    ``role: content`` line per message, framed, as the one fixed user message (chatbot.py:391-398),
    then the first prompt (chatbot.py:242-253: an empty system text, the rule main.py:70 gives, the
    first observation with its valid actions, the task); no reminder; no system text or rules of
    ours. The fixture is in the released layout, in our own words."""
    from recap.recap_prompts import descend_prompt
    from workers.release.texts import release_prompt

    demo = tmp_path / "alfworld-recap/MATRIX/MATRIX/alfworld_3prompts_no_json_all_loc.json"
    demo.parent.mkdir(parents=True)
    example = [
        {"role": "user", "content": "Fixture room.\nYour task is to: warm a fixture."},
        {"role": "assistant", "content": "{}"},
    ]
    demo.write_text(json.dumps({"matrix_heat_0": example, "matrix_put_0": []}))
    release = release_prompt(tmp_path, "recap", "alfworld", "valid_seen", "heat")
    assert release is not None
    fixed = (
        "Solve a task by acting in a household. A worked example follows.\n"
        "user: Fixture room.\nYour task is to: warm a fixture.\nassistant: {}\n\nEXAMPLE OVER\n"
    )
    assert release.messages == (("user", fixed),)
    agent = make_agent("recap", profile="paper", benchmark=get_benchmark("alfworld"), prompts="release")
    assert agent.config.reminder_period is None  # the released ALFWorld code sends no reminder
    work = type("W", (), {"benchmark": "alfworld", "env_options": ()})()
    env = bench.make(HEAT_ID, **env_options_for(work, agent))  # type: ignore[arg-type]
    replies = [{"think": "find the apple", "subtasks": ["find an apple", "heat it"]}, STOP]
    client = ScriptedClient(replies)
    try:
        agent.run(env, client, episode_id="ep", demonstration=release)
    finally:
        env.close()
    first = [(m.role, m.content) for m in client.requests[0].messages]
    assert first == [
        ("user", fixed),
        (
            "user",
            f"\n\n\nThe environment's rule:\n{T.RELEASE_ALFWORLD_RULE}\n\n{HEAT_START}{START_LIST}\n\nThe task at hand: {GOAL}\n",
        ),
    ]
    assert client.requests[1].messages[-1].content == descend_prompt("find an apple")
