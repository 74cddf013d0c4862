"""The one-shot demonstrations: replay environments, reply scripts, the household recorder."""

from __future__ import annotations

import json

import pytest

from recap.env import EnvError
from tests.workers.envs.alfworld.helpers import walk_recap
from workers.envs.alfworld.demos import STYLES, demo_task_types, demonstration_for, recording_for, replies_for
from workers.envs.alfworld.household import Place, Scene, record
from workers.envs.alfworld.replay import ReplayEnvironment
from workers.envs.alfworld.task_types import TASK_TYPES

VERSIONS = ("2.1.1", "2.1.2")
CASES = [(t, v) for t in TASK_TYPES for v in VERSIONS]


def test_one_demonstration_per_task_type():
    assert tuple(demo_task_types()) == tuple(TASK_TYPES)
    for short in TASK_TYPES:
        demo = demonstration_for(short)
        assert demo.name == f"alfworld-{short}"
        assert set(demo.replies) == set(STYLES) == {"recap", "react", "act", "cot", "standard"}
    with pytest.raises(
        ValueError, match="^no ALFWorld demonstration for 'boil'; task types: put, clean, heat, cool, examine, puttwo$"
    ):
        demonstration_for("boil")


@pytest.mark.parametrize(("short", "version"), CASES)
def test_react_and_act_actions_win_the_replay(short, version):
    demo = demonstration_for(short, version)
    react, act = demo.replies["react"], demo.replies["act"]
    assert [r["action"] for r in react] == [r["action"] for r in act]
    assert all(set(r) == {"think", "action"} and r["think"] for r in react)
    assert all(set(r) == {"action"} for r in act)
    env = demo.make_env()
    assert isinstance(env, ReplayEnvironment)
    assert (env.split, env.task, env.invalid_action_mode) == (short, TASK_TYPES[short], "step")
    reset = env.reset()
    assert reset.observation.endswith(f"\n\nYour task is to: {reset.goal}.")
    valid = reset.valid_actions
    for i, reply in enumerate(act):
        assert reply["action"] in valid
        step = env.step(reply["action"])
        valid = step.valid_actions
        assert step.done == step.success == (i == len(act) - 1)
    wording = "put " if version == "2.1.1" else "move "
    other = "move " if version == "2.1.1" else "put "
    actions = [r["action"] for r in act]
    assert any(a.startswith(wording) for a in actions) == (short != "examine")
    assert not any(a.startswith(other) for a in actions)


@pytest.mark.parametrize(("short", "version"), CASES)
def test_recap_replies_follow_the_protocol_call_order(short, version):
    demo = demonstration_for(short, version)
    replies = demo.replies["recap"]
    assert all(set(r) == {"think", "subtasks"} and r["think"] for r in replies)
    walk = walk_recap(demo.make_env(), replies)
    assert walk["won"] is True
    assert walk["calls"] == len(replies), "every reply is used, none is left over"
    assert walk["actions"] == [r["action"] for r in demo.replies["act"]]
    assert walk["depth"] >= (2 if short in ("clean", "heat", "puttwo") else 1)


def test_recap_shows_both_shortcut_and_one_item_descend():
    """The put demo reaches its last action through a descend call that names one valid action."""
    replies = replies_for("put")["recap"]
    assert replies[-2]["subtasks"] == ["place cellphone 2 on bed 1"]
    assert replies[-1]["subtasks"] == ["put cellphone 2 in/on bed 1"]
    assert replies_for("put", "2.1.2")["recap"][-1]["subtasks"] == ["move cellphone 2 to bed 1"]
    # thoughts are the same prose in both versions
    assert [r["think"] for r in replies] == [r["think"] for r in replies_for("put", "2.1.2")["recap"]]


def test_recorded_text_matches_alfworld_wording():
    rec = recording_for("put")
    assert rec.goal == "put some cellphone on bed"
    assert rec.observation == (
        "You are in the middle of a room. Looking quickly around you, you see a bed 1, a desk 1, "
        "a drawer 2, a drawer 1, a dresser 1, a garbagecan 1, a shelf 2, a shelf 1, and a sidetable 1."
        "\n\nYour task is to: put some cellphone on bed."
    )
    assert [s.observation for s in rec.steps] == [
        "You arrive at loc 4. On the desk 1, you see a alarmclock 1, a creditcard 1, and a pen 2.",
        "You arrive at loc 17. On the dresser 1, you see a cd 2, a cellphone 2, and a mug 1.",
        "You pick up the cellphone 2 from the dresser 1.",
        "You arrive at loc 9. On the bed 1, you see a laptop 1, and a pillow 1.",
        "You put the cellphone 2 in/on the bed 1.",
    ]
    assert rec.steps[1].valid_actions == (
        "examine dresser 1",
        "go to bed 1",
        "go to desk 1",
        "go to drawer 1",
        "go to drawer 2",
        "go to garbagecan 1",
        "go to shelf 1",
        "go to shelf 2",
        "go to sidetable 1",
        "inventory",
        "look",
        "take cd 2 from dresser 1",
        "take cellphone 2 from dresser 1",
        "take mug 1 from dresser 1",
    )
    assert rec.steps[2].valid_actions[:2] == ("examine cellphone 2", "examine dresser 1")
    assert "put cellphone 2 in/on dresser 1" in rec.steps[2].valid_actions
    rec12 = recording_for("put", "2.1.2")
    assert rec12.steps[1].observation == "You arrive at dresser 1. On the dresser 1, you see a cd 2, a cellphone 2, and a mug 1."
    assert rec12.steps[-1].observation == "You move the cellphone 2 to the bed 1."
    assert "help" in rec12.valid_actions and "help" not in rec.valid_actions


def test_closed_receptacles_tools_and_lamps():
    heat = recording_for("heat")
    by_action = {s.action: s for s in heat.steps}
    assert by_action["go to fridge 1"].observation == "You arrive at loc 16. The fridge 1 is closed."
    assert "take potato 1 from fridge 1" not in by_action["go to fridge 1"].valid_actions
    assert by_action["open fridge 1"].observation == (
        "You open the fridge 1. The fridge 1 is open. In it, you see a egg 2, a potato 1, and a tomato 2."
    )
    assert "close fridge 1" in by_action["open fridge 1"].valid_actions
    assert "heat potato 1 with microwave 1" in by_action["go to microwave 1"].valid_actions
    assert by_action["heat potato 1 with microwave 1"].observation == "You heat the potato 1 using the microwave 1."
    examine = recording_for("examine")
    assert examine.steps[-1].observation == "You turn on the desklamp 1."
    assert "take desklamp 1 from sidetable 1" not in examine.steps[-2].valid_actions
    puttwo = recording_for("puttwo")
    assert [s.observation for s in puttwo.steps if s.action == "inventory"] == ["You are not carrying anything."]


def test_replay_answers_like_the_game_and_refuses_to_leave_its_script():
    env = demonstration_for("cool").make_env()
    with pytest.raises(EnvError, match="call reset\\(\\) before step\\(\\)$"):
        env.step("look")
    start = env.reset()
    step = env.step("take tomato 1 from diningtable 1")  # not valid yet
    assert (step.observation, step.valid_actions, step.done, step.info["steps"]) == (
        "Nothing happens.",
        start.valid_actions,
        False,
        1,
    )
    with pytest.raises(EnvError) as err:
        env.step("go to fridge 1")
    assert str(err.value) == (
        "alfworld-demo/cool/demo-cool: replay cannot follow 'go to fridge 1'; the recording continues with 'go to diningtable 1'"
    )
    assert env.expert_plan()[0] == "go to diningtable 1"
    assert env.rules() == demonstration_for("cool").make_env().rules() and "in/on" in env.rules()
    assert env.demonstration() is None


def test_replay_step_cap():
    demo = demonstration_for("put", max_steps=2)
    env = demo.make_env()
    env.reset()
    env.step("nonsense")
    last = env.step("nonsense")
    assert (last.done, last.success) == (True, False)
    with pytest.raises(EnvError, match="the episode is over"):
        env.step("go to desk 1")


def test_recorder_rejects_a_step_that_is_not_admissible():
    scene = Scene((Place("drawer 1", 3, ("pen 1",), openable=True), Place("desk 1", 5)), goal="put a pen in desk")
    with pytest.raises(ValueError) as err:
        record(
            scene,
            ["go to drawer 1", "take pen 1 from drawer 1"],
            name="x",
            split="put",
            task="pick_and_place_simple",
            version="2.1.1",
        )
    assert str(err.value) == "demonstration 'x' step 1: 'take pen 1 from drawer 1' is not admissible there"
    ok = record(
        scene,
        ["go to drawer 1", "open drawer 1", "take pen 1 from drawer 1", "go to desk 1", "put pen 1 in/on desk 1"],
        name="x",
        split="put",
        task="pick_and_place_simple",
        version="2.1.1",
    )
    assert ok.steps[-1].won and not any(s.won for s in ok.steps[:-1])
    assert ok.steps[-1].valid_actions == ("examine desk 1", "go to drawer 1", "inventory", "look", "take pen 1 from desk 1")


@pytest.mark.parametrize(("short", "version"), CASES)
def test_cot_and_standard_plans_win_the_replay_and_render(short, version):
    """CoT/Standard on ALFWorld: one plan with every demonstration action, in the version's
    wording; rendering runs the agent itself on the replay, so the plan must reach the goal."""
    from recap.baselines import CoTAgent, PlanConfig, StandardAgent

    demo = demonstration_for(short, version)
    actions = [a["action"] for a in demo.replies["act"]]
    assert demo.replies["standard"] == [{"actions": actions}]
    (cot,) = demo.replies["cot"]
    assert cot["actions"] == actions and cot["think"].startswith("I write the whole plan now, one step per action")
    assert cot["think"].count("(") >= len(actions)
    for agent in (CoTAgent(PlanConfig()), StandardAgent(PlanConfig())):
        text = agent.render_demonstration(demo)
        assert text.endswith("[End of example: the goal was reached.]")
        assert json.dumps(actions[-1])[1:-1] in text
