"""Blocksworld: the small deterministic built-in environment.

It needs no data files and no optional packages, so the method's tests, the demo and the
pipeline's own tests can run anywhere. It is a real environment (state, valid actions, goal
check, an expert planner from any state), just a small one: a few lettered blocks in towers on a
table and one gripper. Instances are ``blocksworld/<n>@<layout seed>`` (n blocks, start and goal drawn from the layout seed).
"""

from __future__ import annotations

import math
import random
import re
from dataclasses import dataclass

from recap.demo_script import DemoScript
from recap.env import Demonstration, Environment, InvalidActionError, Reset, Step, UnknownInstanceError

RULES = (
    "There are lettered blocks standing in towers on a table, and one gripper.\n"
    "- The gripper holds at most one block at a time.\n"
    "- Only a clear block (nothing on top of it) can be picked up or unstacked.\n"
    "- 'pick up X' takes a clear block X from the table; 'unstack X from Y' takes X off block Y.\n"
    "- 'put down X' places the held block on the table; 'stack X on Y' places it on a clear block Y.\n"
    "- The goal names one tower from the bottom up; other blocks may be anywhere."
)

HINTS = (
    "- the action must be copied exactly from the valid actions;\n"
    "- the gripper may already be holding a block;\n"
    "- the block may not be clear (another block is on it)."
)

_ID = re.compile(r"^blocksworld/(\d+)@(\d+)$")
#: the largest seed an instance id may carry: the sweep's seed bound (``pipeline.spec.SEED_MAX``,
#: which recap cannot import; tests/pipeline/test_spec_units.py checks they agree)
SEED_MAX = 2**31 - 1
LETTERS = "ABCDEFGH"


@dataclass
class _State:
    towers: list[list[str]]  # bottom -> top
    holding: str | None


def _valid_actions(s: _State) -> tuple[str, ...]:
    acts: list[str] = []
    tops = [t[-1] for t in s.towers if t]
    if s.holding is None:
        for t in s.towers:
            if len(t) == 1:
                acts.append(f"pick up {t[0]}")
            elif len(t) > 1:
                acts.append(f"unstack {t[-1]} from {t[-2]}")
    else:
        acts.append(f"put down {s.holding}")
        acts += [f"stack {s.holding} on {top}" for top in sorted(tops)]
    return tuple(sorted(acts))


def _observation(s: _State, valid: tuple[str, ...]) -> str:
    lines = []
    for t in sorted((t for t in s.towers if t), key=lambda t: t[0]):
        lines.append("Tower on the table: " + ", ".join(t) + f" (top: {t[-1]})")
    lines.append(f"The gripper holds {s.holding}." if s.holding else "The gripper is empty.")
    lines.append("Valid Actions:\n" + "\n".join(valid))
    return "\n".join(lines)


def _apply(s: _State, action: str) -> None:
    words = action.split()
    if action.startswith("pick up "):
        b = words[2]
        s.towers = [t for t in s.towers if t != [b]]
        s.holding = b
    elif action.startswith("unstack "):
        b = words[1]
        for t in s.towers:
            if t and t[-1] == b:
                t.pop()
        s.holding = b
    elif action.startswith("put down "):
        s.towers.append([words[2]])
        s.holding = None
    elif action.startswith("stack "):
        b, target = words[1], words[3]
        for t in s.towers:
            if t and t[-1] == target:
                t.append(b)
        s.holding = None


def _goal_met(s: _State, goal: list[str]) -> bool:
    return any(t[: len(goal)] == goal for t in s.towers)


def expert_plan_for(s: _State, goal: list[str]) -> list[str]:
    """Put every block that is not part of a correct goal prefix on the table, then build."""
    sim = _State([list(t) for t in s.towers], s.holding)
    plan: list[str] = []

    def do(a: str) -> None:
        plan.append(a)
        _apply(sim, a)

    def correct_prefix() -> list[str]:
        """The longest bottom part of a tower that matches goal[:k]."""
        best: list[str] = []
        for t in sim.towers:
            k = 0
            while k < min(len(t), len(goal)) and t[k] == goal[k]:
                k += 1
            if k > len(best):
                best = t[:k]
        return best

    if sim.holding:
        held, base = sim.holding, correct_prefix()
        tower = next((t for t in sim.towers if base and t[: len(base)] == base), None)
        fits = len(base) < len(goal) and goal[len(base)] == held
        if fits and base and tower is not None and len(tower) == len(base):
            do(f"stack {held} on {base[-1]}")  # the held block is the next one of the tower
        else:
            do(f"put down {held}")
    base = correct_prefix()
    for t in list(sim.towers):
        keep = len(base) if t[: len(base)] == base and base else 0
        while len(t) > max(keep, 1):
            do(f"unstack {t[-1]} from {t[-2]}")
            do(f"put down {sim.holding}")
    if _goal_met(sim, goal):
        return plan
    for i in range(len(base), len(goal)):
        b = goal[i]
        do(f"pick up {b}")
        if i == 0:
            do(f"put down {b}")
        else:
            do(f"stack {b} on {goal[i - 1]}")
    return plan


class BlocksworldEnv(Environment):
    """One Blocksworld instance: start ``towers`` (each listed bottom to top) and a ``goal`` tower,
    bottom up. Invalid actions are rejected; the episode ends at the goal or after ``max_steps``
    (``step_multiplier`` x the expert plan's length)."""

    benchmark = "blocksworld"
    invalid_action_mode = "reject"
    #: every observation ends with its "Valid Actions:" list
    lists_valid_actions = True

    def __init__(
        self,
        towers: list[list[str]],
        goal: list[str],
        *,
        instance_id: str,
        layout_seed: int = 0,
        step_multiplier: float = 4.0,
        demo: bool = True,
    ):
        self._start = [list(t) for t in towers]
        self._goal = list(goal)
        self.instance_id = instance_id
        self.split = f"{sum(len(t) for t in towers)}_blocks"
        self.task = f"tower_{''.join(goal)}"
        self.layout_seed = layout_seed
        self._with_demo = demo
        self.optimal_steps = len(expert_plan_for(_State([list(t) for t in towers], None), goal))
        self.step_multiplier = step_multiplier
        self.max_steps = max(1, math.ceil(self.optimal_steps * step_multiplier))
        self._state = _State([list(t) for t in towers], None)
        self._valid: tuple[str, ...] = ()
        self._steps_taken = 0

    def goal_text(self) -> str:
        g = self._goal
        return (
            "Build one tower with " + ", then ".join([f"{g[0]} on the table"] + [f"{b} on {a}" for a, b in zip(g, g[1:])]) + "."
        )

    def reset(self) -> Reset:
        self._state = _State([list(t) for t in self._start], None)
        self._steps_taken = 0
        self._valid = _valid_actions(self._state)
        return Reset(_observation(self._state, self._valid), self._valid, self.goal_text())

    def step(self, action: str) -> Step:
        if action not in self._valid:
            raise InvalidActionError(f"{action!r} is not a valid action here")
        _apply(self._state, action)
        self._steps_taken += 1
        self._valid = _valid_actions(self._state)
        success = _goal_met(self._state, self._goal)
        done = success or self._steps_taken >= self.max_steps
        info = {"steps": self._steps_taken, "max_steps": self.max_steps}
        return Step(_observation(self._state, self._valid), self._valid, done, success, info)

    def rules(self) -> str:
        return RULES

    def failure_hints(self) -> str:
        return HINTS

    def expert_plan(self) -> list[str]:
        return expert_plan_for(self._state, self._goal)

    def demonstration(self) -> Demonstration | None:
        return DEMONSTRATION if self._with_demo else None


def _random_instance(n: int, layout_seed: int) -> tuple[list[list[str]], list[str]]:
    rng = random.Random(layout_seed * 1000 + n)
    blocks = list(LETTERS[:n])
    while True:
        order = blocks[:]
        rng.shuffle(order)
        towers: list[list[str]] = []
        for b in order:
            if towers and rng.random() < 0.5:
                rng.choice(towers).append(b)
            else:
                towers.append([b])
        goal = blocks[:]
        rng.shuffle(goal)
        if not _goal_met(_State(towers, None), goal):
            return towers, goal


# -- the demonstration: C sits on A, B alone; goal A, B, C -----------------------------------
def _demo_env() -> BlocksworldEnv:
    return BlocksworldEnv([["A", "C"], ["B"]], ["A", "B", "C"], instance_id="blocksworld/demo", demo=False)


_DEMO_ACTIONS = ("unstack C from A", "put down C", "pick up B", "stack B on A", "pick up C", "stack C on B")

#: the example written once; every method derives its own replies from it (recap.demo_script)
DEMO_SCRIPT = DemoScript(
    actions=_DEMO_ACTIONS,
    step_thoughts=(
        "A must be the base but C is on it, so C has to move first.",
        "I hold C; put it on the table for now.",
        "A is clear. B goes on A next.",
        "I hold B.",
        "Now C on top of B.",
        "I hold C; this completes the tower.",
    ),
    plan_thought="C blocks A, so move C to the table, then stack B on A and C on B.",
    decomposition=(
        (
            "A must be the base, but C is sitting on it. First clear A, then build B and C on top.",
            ("clear block A", "build B on A and C on B"),
        ),
        ("Only C is on A, so moving C to the table clears it.", ("unstack C from A", "put down C")),
        ("I hold C; putting it down leaves A clear.", ("put down C",)),
        ("C is on the table and A has nothing on it, so A is clear.", ()),
        ("A is clear on the table; what is left is building the tower.", ("build B on A and C on B",)),
        (
            "B and C are both alone on the table: move B onto A, then C onto B.",
            ("pick up B", "stack B on A", "pick up C", "stack C on B"),
        ),
        ("I hold B; it goes on A next.", ("stack B on A", "pick up C", "stack C on B")),
        ("B is on A. Now C.", ("pick up C", "stack C on B")),
        ("I hold C; stacking it on B finishes the tower.", ("stack C on B",)),
    ),
)

DEMONSTRATION = Demonstration(name="blocksworld/demo", make_env=_demo_env, script=DEMO_SCRIPT)


class _Benchmark:
    name = "blocksworld"
    SIZES = (3, 4, 5)
    LAYOUT_SEEDS = (1, 2, 3)

    def list_instances(self, selector: str | None = None) -> list[str]:
        ids = [f"blocksworld/{n}@{s}" for n in self.SIZES for s in self.LAYOUT_SEEDS]
        if selector in (None, "", "all"):
            return ids
        sel = selector.removeprefix("blocksworld/")
        picked = [i for i in ids if i == f"blocksworld/{sel}" or i.split("/")[1].split("@")[0] == sel]
        if not picked:
            raise UnknownInstanceError(
                f"no blocksworld instance matches {selector!r}; sizes {list(self.SIZES)}, e.g. blocksworld/3@1"
            )
        return picked

    def canonical_id(self, instance_id: str) -> str:
        """``blocksworld/<n>@<seed>`` with both numbers written without leading zeros
        (``blocksworld/03@001`` -> ``blocksworld/3@1``), the seed within ``0..SEED_MAX``; any
        other id as written (:meth:`make` refuses it)."""
        m = _ID.match(instance_id)
        if not m:
            return instance_id
        seed = int(m.group(2))
        if seed > SEED_MAX:
            raise UnknownInstanceError(f"blocksworld instance {instance_id!r}: the seed must be within 0..{SEED_MAX}")
        return f"blocksworld/{int(m.group(1))}@{seed}"

    def make(self, instance_id: str, *, step_multiplier: float = 4.0, **_options: object) -> BlocksworldEnv:
        m = _ID.match(instance_id)
        if not m or not 2 <= int(m.group(1)) <= len(LETTERS):
            raise UnknownInstanceError(
                f"unknown blocksworld instance {instance_id!r}; use blocksworld/<n>@<seed> with 2 <= n <= {len(LETTERS)}"
            )
        n, layout_seed = int(m.group(1)), int(m.group(2))
        towers, goal = _random_instance(n, layout_seed)
        return BlocksworldEnv(towers, goal, instance_id=instance_id, layout_seed=layout_seed, step_multiplier=step_multiplier)


BENCHMARK = _Benchmark()
