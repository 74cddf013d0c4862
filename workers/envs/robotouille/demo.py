"""The one-shot demonstration: an onion cheese sandwich in the synchronous training kitchen.

As in the paper, every Robotouille agent (sync and async) is shown the same solved training task:
``instances_train/synchronous_train/0_cheese_onion_sandwich_26.json``, read at run time from the
user's data folder and run on our engine. The example is written once (:func:`script`): its 22
actions with the thought before each, the plan's thought, and the goal's decomposition. Each agent
class derives its model replies from it, and renders them by running itself on ``make_env()``
with a scripted model, so the demonstration always has the exact format of the agent's own prompts.

The decomposition (ReCAP's replies, in call order) forms a three-level tree: the root splits the recipe into four dish steps, the
first of which ("prepare a cut onion") splits again into clearing a board, fetching the onion and
cutting it, each of which lists its primitive actions. All thinks are this project's own words.
"""

from __future__ import annotations

from collections.abc import Callable

from recap.demo_script import DemoScript
from recap.env import Demonstration, Environment

#: one decomposition reply: (think, subtasks)
Step = tuple[str, tuple[str, ...]]

DEMO_NAME = "robotouille/onion_cheese_sandwich"
DEMO_SPLIT = "synchronous"
DEMO_TASK = "0_cheese_onion_sandwich"
DEMO_SEED = 26

# the 22 actions, grouped by the subtask that performs them
CLEAR_BOARD = [
    "Move robot1 from stove1 to board1",
    "Pick up lettuce1 from board1 using robot1",
    "Move robot1 from board1 to table2",
    "Place lettuce1 on table2 using robot1",
]
FETCH_ONION = [
    "Move robot1 from table2 to fryer1",
    "Pick up onion1 from fryer1 using robot1",
    "Move robot1 from fryer1 to board1",
    "Place onion1 on board1 using robot1",
]
CUT_ONION = ["Cut onion1 on board1 using robot1"] * 3
STACK_ONION = [
    "Pick up onion1 from board1 using robot1",
    "Move robot1 from board1 to table1",
    "Stack onion1 on top of bread1 using robot1",
]
STACK_CHEESE = [
    "Move robot1 from table1 to sink3",
    "Pick up cheese1 from sink3 using robot1",
    "Move robot1 from sink3 to table1",
    "Stack cheese1 on top of onion1 using robot1",
]
TOP_BREAD = [
    "Move robot1 from table1 to stove1",
    "Pick up bread2 from stove1 using robot1",
    "Move robot1 from stove1 to table1",
    "Stack bread2 on top of cheese1 using robot1",
]
ACTIONS = CLEAR_BOARD + FETCH_ONION + CUT_ONION + STACK_ONION + STACK_CHEESE + TOP_BREAD

# --------------------------------------------------------------------------- the decomposition
PREPARE = "Prepare a cut onion on board1"
STACK_ONION_TASK = "Stack the cut onion on bread1 at table1"
CHEESE_TASK = "Stack cheese1 on top of the onion"
BREAD_TASK = "Finish the sandwich with bread2 on top"
CLEAR_TASK = "Clear lettuce1 off board1"
FETCH_TASK = "Bring onion1 onto board1"
CUT_TASK = "Cut onion1 three times"


def _reply(think: str, subtasks: list[str]) -> Step:
    return (think, tuple(subtasks))


def _action_list_node(descend_think: str, actions: list[str], thinks: list[str], closing: str | None) -> list[Step]:
    """Descend reply listing ``actions``, then one refine reply after each action.

    ``thinks[k]`` is the think after action k (the remaining actions follow); ``closing`` is the
    think of the final refine (empty list: the node is done), or None when the episode ends with
    the last action (the environment reports done and no further call is made).
    """
    replies = [_reply(descend_think, actions)]
    for k in range(len(actions) - 1):
        replies.append(_reply(thinks[k], actions[k + 1 :]))
    if closing is not None:
        replies.append(_reply(closing, []))
    return replies


def decomposition() -> list[Step]:
    """The goal's decomposition as (think, subtasks), in ReCAP's call order: the root's reply, the
    onion's preparation subtree, then the sandwich built back at the root."""
    root_plan = [PREPARE, STACK_ONION_TASK, CHEESE_TASK, BREAD_TASK]
    return [
        _reply(
            "The sandwich needs a bottom slice of bread directly on a table, a cut onion and cheese1 on it, "
            "and a second slice on top. bread1 already lies alone on table1, so it can stay there as the "
            "bottom slice. The onion is the only ingredient that needs work: it must be cut on a board. "
            "After that I stack onion, cheese and bread2 on bread1, in that order.",
            root_plan,
        ),
        *_prepare_onion(),
        *_build_sandwich(root_plan),
    ]


def _prepare_onion() -> list[Step]:
    """Descending into PREPARE: free board1, fetch onion1, cut it; a refine reply after each child."""
    return [
        _reply(
            "To cut an onion I need an empty cutting board. board1 holds lettuce1 and board2 holds bottombun1; "
            "neither is part of this sandwich, so I free board1 by moving the lettuce to an empty table. "
            "Then I fetch onion1 from fryer1, put it on board1 and cut it three times.",
            [CLEAR_TASK, FETCH_TASK, CUT_TASK],
        ),
        *_action_list_node(
            "I stand at stove1. I go to board1, pick up lettuce1 and leave it on table2, which is empty.",
            CLEAR_BOARD,
            [
                "I am at board1 and lettuce1 is the only thing on it, so I can pick it up.",
                "I hold lettuce1. table2 has nothing on it, so I carry the lettuce there.",
                "I am at the empty table2 holding lettuce1; I put it down here.",
            ],
            "lettuce1 is on table2 and board1 is empty now. This subtask is done.",
        ),
        _reply(
            "board1 is free. Next I bring onion1 over from fryer1, then cut it.",
            [FETCH_TASK, CUT_TASK],
        ),
        *_action_list_node(
            "onion1 lies alone on fryer1. I walk there, pick it up, return to board1 and place it on the board.",
            FETCH_ONION,
            [
                "I reached fryer1; onion1 has nothing on top, so I pick it up.",
                "I hold onion1 and head back to the empty board1.",
                "I am at board1 with the onion; placing it puts it directly on the board.",
            ],
            "onion1 is on board1 with nothing above it. This subtask is done.",
        ),
        _reply(
            "The onion is on the cutting board and I am standing there. All that is left is to cut it.",
            [CUT_TASK],
        ),
        *_action_list_node(
            "A cut only counts after three cuts in a row, so I cut onion1 three times.",
            CUT_ONION,
            [
                "One cut done; the onion is not cut yet. Two more.",
                "Two cuts done. One more cut finishes it.",
            ],
            "The observation now says onion1 is cut. This subtask is done.",
        ),
        _reply(
            "onion1 is cut, so preparing the onion is finished.",
            [],
        ),
    ]


def _build_sandwich(root_plan: list[str]) -> list[Step]:
    """Back at the root: stack the onion, the cheese and the top slice on bread1, one refine reply after each."""
    return [
        _reply(
            "The cut onion is waiting on board1. Now I build the sandwich on bread1 at table1: onion first, "
            "then cheese1, then bread2 on top.",
            root_plan[1:],
        ),
        *_action_list_node(
            "I am at board1 next to the cut onion. I pick it up, go to table1 and stack it on bread1.",
            STACK_ONION,
            [
                "I hold the cut onion; table1 with bread1 is where the sandwich goes.",
                "At table1; bread1 has nothing above it, so the onion goes right on top of it.",
            ],
            "onion1 sits directly on bread1. This subtask is done.",
        ),
        _reply(
            "The onion is on the bottom slice. Next the cheese, then the top slice.",
            root_plan[2:],
        ),
        *_action_list_node(
            "cheese1 lies alone on sink3. I fetch it and stack it on the onion at table1.",
            STACK_CHEESE,
            [
                "At sink3; cheese1 is free to pick up.",
                "I hold cheese1 and carry it back to the sandwich at table1.",
                "At table1; the onion is the top of the stack, so the cheese goes on it.",
            ],
            "cheese1 is on top of the onion. This subtask is done.",
        ),
        _reply(
            "Bread, onion and cheese are stacked. Only the top slice is missing: bread2 on stove1.",
            root_plan[3:],
        ),
        *_action_list_node(
            "bread2 lies alone on stove1. I fetch it and put it on top of the cheese to close the sandwich.",
            TOP_BREAD,
            [
                "At stove1; bread2 can be picked up.",
                "I hold bread2 and walk back to table1.",
                "At table1; stacking bread2 on the cheese completes the sandwich.",
            ],
            None,
        ),
    ]


# --------------------------------------------------------------- the thought before each action, the plan
REACT_THINKS = [
    "Cutting needs an empty board; board1 is taken by lettuce1, which this sandwich does not use. I go to board1.",
    "I pick up lettuce1 to free the board.",
    "table2 is empty; I carry the lettuce there.",
    "I put the lettuce down on table2; board1 is now free.",
    "The onion to cut is onion1 on fryer1. I go there.",
    "onion1 has nothing on it; I pick it up.",
    "I take the onion to the free board1.",
    "I place onion1 directly on board1.",
    "First of three cuts.",
    "Second cut.",
    "Third cut; after this onion1 is cut.",
    "onion1 is cut. I pick it up to put it on the sandwich.",
    "bread1 already lies on table1 as the bottom slice; I go there.",
    "I stack the cut onion on bread1.",
    "Next is cheese1, which is on sink3.",
    "I pick up cheese1.",
    "Back to the sandwich at table1.",
    "I stack cheese1 on the onion.",
    "The top slice is bread2 on stove1; I go there.",
    "I pick up bread2.",
    "Back to table1 with the last slice.",
    "Stacking bread2 on the cheese finishes the sandwich.",
]

PLAN_THINK = (
    "The sandwich is built on bread1, which already lies on table1. The onion must be cut first, and "
    "the only boards are taken, so I move lettuce1 off board1 to the empty table2, bring onion1 from "
    "fryer1 to board1 and cut it three times. Then I stack the onion on bread1, fetch cheese1 from "
    "sink3 and stack it, and finish with bread2 from stove1 on top."
)


def script() -> DemoScript:
    """The example written once; every method derives its own replies from it."""
    return DemoScript(
        actions=tuple(ACTIONS), step_thoughts=tuple(REACT_THINKS), plan_thought=PLAN_THINK, decomposition=tuple(decomposition())
    )


def make_demonstration(make_env: Callable[[], Environment]) -> Demonstration:
    """Robotouille's one-shot demonstration: the example written once (:func:`script`), played on
    the environment ``make_env`` builds."""
    return Demonstration(name=DEMO_NAME, make_env=make_env, script=script())
