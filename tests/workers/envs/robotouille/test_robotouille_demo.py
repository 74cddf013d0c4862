"""The one-shot demonstration: its replies drive the training kitchen to success for every style."""

from __future__ import annotations

import pytest

from recap.env import Demonstration
from workers.envs.robotouille import BENCHMARK
from workers.envs.robotouille.demo import ACTIONS

from .helpers import DATA, require_data


@pytest.fixture()
def demo() -> Demonstration:
    require_data()
    env = BENCHMARK.make("robotouille/asynchronous/7_tomato_soup_and_lettuce_chicken_sandwich@42", data_dir=str(DATA))
    demo = env.demonstration()
    assert isinstance(demo, Demonstration)
    return demo


def test_demo_is_the_sync_training_kitchen_for_sync_and_async(demo):
    assert demo.name == "robotouille/onion_cheese_sandwich"
    sync = BENCHMARK.make("robotouille/synchronous/0_cheese_sandwich@42", data_dir=str(DATA)).demonstration()
    assert sync.name == demo.name and sync.replies == demo.replies
    env = demo.make_env()
    reset = env.reset()
    assert reset.goal == "Prepare a onion cheese sandwich on a table"
    assert env.split == "synchronous" and env.layout_seed == 26
    assert sorted(demo.replies) == ["act", "cot", "react", "recap", "standard"]


def _flat_actions(style: str, replies) -> list[str]:
    if style in ("react", "act"):
        return [r["action"] for r in replies]
    (only,) = replies
    return list(only["actions"])


@pytest.mark.parametrize("style", ["react", "act", "cot", "standard"])
def test_flat_styles_solve_the_demo(demo, style):
    replies = demo.replies[style]
    for reply in replies:
        expected = {"react": {"think", "action"}, "act": {"action"}, "cot": {"think", "actions"}, "standard": {"actions"}}[style]
        assert set(reply) == expected
    actions = _flat_actions(style, replies)
    assert actions == ACTIONS and len(actions) == 22
    env = demo.make_env()
    env.reset()
    for k, action in enumerate(actions, start=1):
        step = env.step(action)
        assert step.done == (k == len(actions))
    assert step.success


class _ScriptedRecap:
    """Minimal ReCAP control loop (the call order of recap/recap_agent.py) fed with scripted replies.

    Records every call as (purpose, task) so the test can check the tree the replies describe.
    """

    def __init__(self, env, replies):
        self.env = env
        self.replies = list(replies)
        self.calls: list[tuple[str, str]] = []
        self.actions: list[str] = []
        self.valid = ()
        self.done = False
        self.success = False

    def ask(self, purpose: str, task: str):
        self.calls.append((purpose, task))
        assert self.replies, f"no reply left for {purpose} call on {task!r}"
        reply = self.replies.pop(0)
        assert set(reply) == {"think", "subtasks"} and reply["think"]
        return reply["subtasks"]

    def execute(self, action: str) -> None:
        step = self.env.step(action)
        self.actions.append(action)
        self.valid = step.valid_actions
        self.done, self.success = step.done, step.success

    def run(self, goal: str) -> None:
        self.valid = self.env.reset().valid_actions
        subtasks = self.ask("task", goal)
        self.loop(goal, subtasks)

    def loop(self, task: str, subtasks: list[str]) -> None:
        """Run a node until its list is empty (or the episode ends)."""
        while subtasks and not self.done:
            self.descend(subtasks[0])
            if self.done:
                return
            subtasks = self.ask("refine", task)

    def descend(self, child: str) -> None:
        if child in self.valid:  # shortcut: no call
            self.execute(child)
            return
        sub = self.ask("descend", child)
        if len(sub) == 1:
            assert sub[0] in self.valid, f"leaf failure in the demo: {sub[0]!r}"
            self.execute(sub[0])
            return
        self.loop(child, sub)


def test_recap_replies_follow_the_call_order_and_solve_the_demo(demo):
    env = demo.make_env()
    sim = _ScriptedRecap(env, demo.replies["recap"])
    sim.run(env.reset().goal)
    assert sim.success and sim.done
    assert sim.replies == []  # every reply consumed, none missing
    assert sim.actions == ACTIONS
    descends = [task for purpose, task in sim.calls if purpose == "descend"]
    assert descends == [
        "Prepare a cut onion on board1",
        "Clear lettuce1 off board1",
        "Bring onion1 onto board1",
        "Cut onion1 three times",
        "Stack the cut onion on bread1 at table1",
        "Stack cheese1 on top of the onion",
        "Finish the sandwich with bread2 on top",
    ]
    # three levels: root -> dish step -> board/onion subtask -> primitive actions
    refined = {task for purpose, task in sim.calls if purpose == "refine"}
    assert {
        "Prepare a onion cheese sandwich on a table",
        "Prepare a cut onion on board1",
        "Clear lettuce1 off board1",
        "Cut onion1 three times",
    } <= refined
    assert sim.calls[0] == ("task", "Prepare a onion cheese sandwich on a table")
    assert len(sim.calls) == len(demo.replies["recap"])
