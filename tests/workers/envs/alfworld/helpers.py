"""Shared paths and a reference walker of ReCAP's call order for the ALFWorld tests."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from recap.env import Environment

REPO = Path(__file__).resolve().parents[4]
DATA = (REPO / ".." / "shared" / "data" / "alfworld").resolve()
DATA_2_1_2 = (REPO / ".." / "shared" / "data" / "alfworld-2.1.2").resolve()

EXPECTED_COUNTS = {"put": 24, "clean": 31, "heat": 23, "cool": 21, "examine": 18, "puttwo": 17}


def win_by_expert(env: Environment) -> list[str]:
    """Reset, then play the expert plan checking every step; returns the plan played."""
    reset = env.reset()
    plan = env.expert_plan()
    assert plan, "every evaluation game has a walkthrough"
    valid = reset.valid_actions
    for i, action in enumerate(plan):
        assert action in valid, f"{env.instance_id}: expert action {action!r} is not admissible"
        assert env.expert_plan() == plan[i:]
        step = env.step(action)
        valid = step.valid_actions
        assert step.info == {"steps": i + 1, "max_steps": 50, "won": step.success, "admissible_commands": valid}
        assert step.done == (i == len(plan) - 1)
    assert step.success and step.done
    assert env.expert_plan() == []
    return plan


class WalkError(AssertionError):
    pass


def walk_recap(env: Environment, replies: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Play ``replies`` on ``env`` following recap/recap_agent.py literally.

    Returns the number of replies used, the actions executed, the deepest node level and whether
    the episode was won. Written independently of recap/ so the demonstrations are checked
    against the protocol text itself.
    """
    state: dict[str, Any] = {"calls": 0, "actions": [], "done": False, "won": False, "depth": 0}
    valid = env.reset().valid_actions or ()

    def reply() -> list[str]:
        if state["calls"] >= len(replies):
            raise WalkError(f"the protocol needs more than {len(replies)} replies")
        subtasks = list(replies[state["calls"]]["subtasks"])
        state["calls"] += 1
        return subtasks

    def execute(action: str) -> None:
        nonlocal valid
        step = env.step(action)
        valid = step.valid_actions or ()
        state["actions"].append(action)
        state["done"], state["won"] = step.done, step.success

    def run_node(subtasks: list[str], depth: int) -> None:
        state["depth"] = max(state["depth"], depth)
        while subtasks and not state["done"]:
            head = subtasks[0]
            if head in valid:  # shortcut: no call
                execute(head)
            else:
                child = reply()  # descend
                state["depth"] = max(state["depth"], depth + 1)
                if len(child) == 1 and child[0] in valid:
                    execute(child[0])
                elif len(child) == 1:
                    pass  # leaf failure
                elif child:
                    run_node(child, depth + 1)
            if state["done"]:
                return
            subtasks = reply()  # refine this node

    run_node(reply(), 0)
    return state


#: the heat game used by the environment tests, and its first observation (2.1.1 wording)
HEAT_ID = "alfworld/heat/pick_heat_then_place_in_recep-Apple-None-Fridge-10/trial_T20190906_182259_116320"
HEAT_START = (
    "You are in the middle of a room. Looking quickly around you, you see a cabinet 6, a cabinet 5, "
    "a cabinet 4, a cabinet 3, a cabinet 2, a cabinet 1, a coffeemachine 1, a countertop 3, "
    "a countertop 2, a countertop 1, a drawer 3, a drawer 2, a drawer 1, a fridge 1, a garbagecan 1, "
    "a microwave 1, a shelf 3, a shelf 2, a shelf 1, a sinkbasin 1, a stoveburner 4, a stoveburner 3, "
    "a stoveburner 2, a stoveburner 1, and a toaster 1.\n\nYour task is to: heat some apple and put it "
    "in fridge."
)
