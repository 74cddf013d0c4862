"""Demonstrations are written once per benchmark (a method-neutral DemoScript) and each agent
class derives its own replies from it.

The rendered texts must be exactly those of the per-method replies the benchmarks used to write
by hand: ``RENDERED`` holds the sha256 (first 16 hex digits) of the texts the code before the
change rendered, for every method x profile on each benchmark's demonstration (ALFWorld in both
game-file versions, with and without valid actions) and every ReCAP ablation. The full check
(all methods x benchmarks x profiles x ablations x demo_observations, 2,190 texts) was run once
when the scripts were introduced; this keeps a sample of it, plus two texts in full.
"""

from __future__ import annotations

import hashlib
import json

import pytest

from recap import blocksworld
from recap.agent import DemonstrationError
from recap.demo_replies import DemoReplies
from recap.demo_script import DemoScript
from recap.env import Demonstration
from recap.methods import METHODS, make_agent
from workers.envs.alfworld.demos import demonstration_for
from workers.envs.registry import get_benchmark, make_env

DEMOS = {
    "blocksworld": lambda: blocksworld.DEMONSTRATION,
    "robotouille": lambda: make_env("robotouille/synchronous/0_cheese_sandwich@42").demonstration(),
    "alfworld-heat-2.1.2": lambda: demonstration_for("heat", "2.1.2"),
    "alfworld-puttwo-valid-actions": lambda: demonstration_for("puttwo", show_valid_actions=True),
}

#: method|profile|ablation|demonstration -> sha256[:16] of the text rendered before the change;
#: the ``released`` texts of react, act, cot, standard and adapt were recorded again when that
#: profile took the released plain-text reply formats (issue 25; tests/recap/test_text_replies.py
#: checks them in full), and ReAct's ALFWorld text once its observations came from the environment
#: alone (an example game without lists shows none, as the release's example, react.py:206-208) and
#: the plain-text turns stopped repeating a goal the observation already states (as released)
RENDERED = {
    "recap|paper|-|blocksworld": "fa911055cea731cb",
    "recap|paper|-|robotouille": "f5def72e2f9f2958",
    "recap|paper|-|alfworld-heat-2.1.2": "4cc1762740ed9ca9",
    "recap|paper|-|alfworld-puttwo-valid-actions": "bda0e4557be9beb6",
    "recap|released|-|blocksworld": "39bb17065d6957e4",
    "recap|released|-|robotouille": "6eff6314fa3a1bed",
    "recap|released|-|alfworld-heat-2.1.2": "fb4538a97141694e",
    "recap|released|-|alfworld-puttwo-valid-actions": "3bd04461bfd18c27",
    "react|paper|-|blocksworld": "58da378e836de31d",
    "react|paper|-|robotouille": "46988e42d2824a96",
    "react|paper|-|alfworld-heat-2.1.2": "8931193b75f052a5",
    "react|paper|-|alfworld-puttwo-valid-actions": "342e2ed9ec8cf279",
    "react|released|-|blocksworld": "6fe5c912ad7404e5",
    "react|released|-|robotouille": "63bec28d093a0e91",
    "react|released|-|alfworld-heat-2.1.2": "6e6e629463cb8972",
    "react|released|-|alfworld-puttwo-valid-actions": "d72a0adcfddf02fc",
    "act|paper|-|blocksworld": "6c0d92271301e108",
    "act|paper|-|robotouille": "fb60788abd86c74a",
    "act|paper|-|alfworld-heat-2.1.2": "ff778c78205476c4",
    "act|paper|-|alfworld-puttwo-valid-actions": "d615a253c6e99e44",
    "act|released|-|blocksworld": "3ed5a3495f45742c",
    "act|released|-|robotouille": "430d04a9fa67b3d1",
    "act|released|-|alfworld-heat-2.1.2": "ff778c78205476c4",
    "act|released|-|alfworld-puttwo-valid-actions": "d615a253c6e99e44",
    "cot|paper|-|blocksworld": "0a039d81304a52df",
    "cot|paper|-|robotouille": "5048d1d1d0526eb3",
    "cot|paper|-|alfworld-heat-2.1.2": "25ba7d7b8a1f37d3",
    "cot|paper|-|alfworld-puttwo-valid-actions": "0485908a4b7d4063",
    "cot|released|-|blocksworld": "03602cf928927887",
    "cot|released|-|robotouille": "b9efab2c88e27385",
    "cot|released|-|alfworld-heat-2.1.2": "25ba7d7b8a1f37d3",
    "cot|released|-|alfworld-puttwo-valid-actions": "0485908a4b7d4063",
    "standard|paper|-|blocksworld": "b2bd0d7a53291624",
    "standard|paper|-|robotouille": "d6b16844ac5e5b8e",
    "standard|paper|-|alfworld-heat-2.1.2": "6d8efbdf738caed3",
    "standard|paper|-|alfworld-puttwo-valid-actions": "3f88f3ef0767f896",
    "standard|released|-|blocksworld": "ad5d0a201e4ff21c",
    "standard|released|-|robotouille": "cb929b8f36ce0ead",
    "standard|released|-|alfworld-heat-2.1.2": "6d8efbdf738caed3",
    "standard|released|-|alfworld-puttwo-valid-actions": "3f88f3ef0767f896",
    "adapt|paper|-|blocksworld": "043272fd701ebc8d",
    "adapt|paper|-|robotouille": "0ce73c1892958d0a",
    "adapt|paper|-|alfworld-heat-2.1.2": "22338baaf1439564",
    "adapt|paper|-|alfworld-puttwo-valid-actions": "50c6e4e087c523b8",
    "adapt|released|-|blocksworld": "2886310da2b3f7a1",
    "adapt|released|-|robotouille": "07bb8d9bec46264d",
    "adapt|released|-|alfworld-heat-2.1.2": "22338baaf1439564",
    "adapt|released|-|alfworld-puttwo-valid-actions": "50c6e4e087c523b8",
    "recap|paper|original|robotouille": "f5def72e2f9f2958",
    "recap|paper|original|alfworld-heat-2.1.2": "4cc1762740ed9ca9",
    "recap|paper|no_think|robotouille": "338ae11be7c065b4",
    "recap|paper|no_think|alfworld-heat-2.1.2": "18f4c2cc75177afc",
    "recap|paper|think_many|robotouille": "67020d1182a94952",
    "recap|paper|think_many|alfworld-heat-2.1.2": "58fcdd0b9faad7c4",
    "recap|paper|name_only|robotouille": "02524c88e01a4cb6",
    "recap|paper|name_only|alfworld-heat-2.1.2": "e2e7484bb6166083",
    "recap|paper|level_2|robotouille": "f5def72e2f9f2958",
    "recap|paper|level_2|alfworld-heat-2.1.2": "4cc1762740ed9ca9",
    "recap|paper|level_3|robotouille": "f5def72e2f9f2958",
    "recap|paper|level_3|alfworld-heat-2.1.2": "4cc1762740ed9ca9",
    "recap|paper|level_4|robotouille": "f5def72e2f9f2958",
    "recap|paper|level_4|alfworld-heat-2.1.2": "4cc1762740ed9ca9",
    "recap|paper|level_5|robotouille": "f5def72e2f9f2958",
    "recap|paper|level_5|alfworld-heat-2.1.2": "4cc1762740ed9ca9",
    "recap|paper|no_shortcut|robotouille": "f5def72e2f9f2958",
    "recap|paper|no_shortcut|alfworld-heat-2.1.2": "4cc1762740ed9ca9",
}


def _text(method: str, profile: str, ablation: str | None, demo_key: str) -> str:
    agent = make_agent(method, profile, ablation, get_benchmark(demo_key.split("-")[0]))
    demo = DEMOS[demo_key]()
    text = agent.render_demonstration(demo)
    if method == "adapt":
        text += "\n<<PLANNER>>\n" + agent.render_planner_demonstration(demo)
    return text


@pytest.mark.parametrize("key", list(RENDERED))
def test_rendered_demonstrations_are_unchanged(key):
    method, profile, ablation, demo_key = key.split("|")
    text = _text(method, profile, None if ablation == "-" else ablation, demo_key)
    assert hashlib.sha256(text.encode()).hexdigest()[:16] == RENDERED[key]


INTRO = "Here is a complete example of the interaction, from the first prompt to the goal being reached."
GOAL = "Build one tower with A on the table, then B on A, then C on B."
ACTIONS = ["unstack C from A", "put down C", "pick up B", "stack B on A", "pick up C", "stack C on B"]


def test_standard_blocksworld_text_in_full():
    text = make_agent("standard").render_demonstration(blocksworld.DEMONSTRATION)
    assert text == (
        f"{INTRO}\n\n[Example prompt]\nInitial observation:\nTower on the table: A, C (top: C)\n"
        "Tower on the table: B (top: B)\nThe gripper is empty.\nValid Actions:\npick up B\nunstack C from A\n\n"
        f"Your goal:\n{GOAL}\n\nReply with your complete plan.\n\n[Example reply]\n"
        f"{json.dumps({'actions': ACTIONS})}\n\n[End of example: the goal was reached.]"
    )


def test_act_blocksworld_text_without_observations_in_full():
    text = make_agent("act", demo_observations="none").render_demonstration(blocksworld.DEMONSTRATION)
    omitted = "(observation left out of this example)"
    parts = [
        INTRO,
        f"[Example prompt]\nInitial observation:\n{omitted}\n\nYour goal:\n{GOAL}\n\nReply with your first action.",
        f'[Example reply]\n{{"action": "{ACTIONS[0]}"}}',
    ]
    for a in ACTIONS[1:]:
        parts += [f"[Example prompt]\nObservation:\n{omitted}", f'[Example reply]\n{{"action": "{a}"}}']
    parts.append("[End of example: the goal was reached.]")
    assert text == "\n\n".join(parts)


@pytest.mark.parametrize("demo_key", ["blocksworld", "robotouille", "alfworld-heat-2.1.2"])
@pytest.mark.parametrize("method", ["recap", "react", "act", "cot", "standard"])
def test_each_transcript_replays_the_replies_its_class_derives_from_the_script(method, demo_key):
    demo = DEMOS[demo_key]()
    agent_cls = METHODS[method][0]
    derived = agent_cls.demo_replies(demo.script)
    assert demo.replies[method] == derived
    text = make_agent(method).render_demonstration(demo)
    replies = [block.split("\n", 1)[1] for block in text.split("\n\n[") if block.startswith("Example reply]")]
    assert replies == [json.dumps(r, ensure_ascii=False) for r in derived]


def test_every_class_derives_its_shape_from_one_script():
    s = blocksworld.DEMO_SCRIPT
    assert METHODS["react"][0].demo_replies(s) == [{"think": t, "action": a} for t, a in zip(s.step_thoughts, ACTIONS)]
    assert METHODS["act"][0].demo_replies(s) == [{"action": a} for a in ACTIONS]
    assert METHODS["cot"][0].demo_replies(s) == [{"think": s.plan_thought, "actions": ACTIONS}]
    assert METHODS["standard"][0].demo_replies(s) == [{"actions": ACTIONS}]
    assert METHODS["recap"][0].demo_replies(s)[3] == {
        "think": "C is on the table and A has nothing on it, so A is clear.",
        "subtasks": [],
    }
    assert len(METHODS["recap"][0].demo_replies(s)) == len(s.decomposition) == 9
    # ADaPT renders two parts (executor from ReAct's replies, planner from the root decomposition)
    assert METHODS["adapt"][0].demo_replies(s) is None
    assert list(blocksworld.DEMONSTRATION.replies) == ["recap", "react", "act", "cot", "standard"]


def test_hand_written_replies_win_and_a_demonstration_without_script_derives_nothing():
    d = blocksworld.DEMONSTRATION
    mine = [{"actions": ["pick up B"]}]
    both = Demonstration("blocksworld/demo-mine", d.make_env, {"standard": mine}, script=d.script)
    assert both.replies["standard"] == mine and both.replies["cot"] == d.replies["cot"]
    assert list(both.replies) == ["standard", "recap", "react", "act", "cot"]
    only = Demonstration("blocksworld/demo-only", d.make_env, {"standard": mine})
    assert dict(only.replies) == {"standard": mine} and "react" not in only.replies
    with pytest.raises(DemonstrationError, match="has no replies for style 'react'"):
        make_agent("react").render_demonstration(only)
    assert DemoReplies(both.replies) == both.replies  # re-wrapping keeps the overrides and the script


def test_a_script_needs_one_thought_per_action():
    with pytest.raises(ValueError, match="one thought per action"):
        DemoScript(actions=("a", "b"), step_thoughts=("t",), plan_thought="p", decomposition=())
    with pytest.raises(ValueError, match="at least one action"):
        DemoScript(actions=(), step_thoughts=(), plan_thought="p", decomposition=())
