"""Record a demonstration episode in an invented household, in ALFWorld's game wording.

A demonstration is written as a small scene (receptacles, their numbers and contents) plus the
commands that solve it. Writing every observation and every valid-action list by hand would be
error-prone, so this module plays the commands on the scene with ALFWorld's visible rules and
phrasing (as observed on the real 2.1.1/2.1.2 games: sorted admissible commands, "You arrive at
loc N.", closed receptacles hide their contents, one object in hand, heating/cooling/cleaning at
the microwave/fridge/sinkbasin, "use" for a lamp on the current receptacle) and stores the result
as a :class:`~workers.envs.alfworld.replay.Recording`. It rejects a command that would not be
admissible, so a demonstration can never show an impossible step.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from workers.envs.alfworld.replay import RecordedStep, Recording
from workers.envs.alfworld.wording import check_version

_TOOL_VERBS = {"sinkbasin": "clean", "bathtubbasin": "clean", "microwave": "heat", "fridge": "cool"}
_FIXED_OBJECTS = ("desklamp",)  # usable in place, never picked up


@dataclass(frozen=True)
class Place:
    """A receptacle of a demonstration scene: its name with number, the loc number shown on arrival, what it
    holds, and whether it opens (then its contents are hidden until opened)."""

    name: str  # "fridge 1"
    loc: int  # the number shown on arrival in 2.1.1 ("You arrive at loc 16.")
    contents: tuple[str, ...] = ()
    openable: bool = False


@dataclass(frozen=True)
class Scene:
    """An invented household for one demonstration: its receptacles, and the task sentence (without its final period)."""

    places: tuple[Place, ...]
    goal: str  # the task sentence without its final period


def _kind_and_number(name: str) -> tuple[str, int]:
    kind, _, number = name.rpartition(" ")
    return kind, -int(number)


def _listing(names: Sequence[str]) -> str:
    """ALFWorld's enumeration: kinds alphabetically, higher numbers first, "and" before the last."""
    items = [f"a {n}" for n in sorted(names, key=_kind_and_number)]
    if not items:
        return "nothing"
    if len(items) == 1:
        return items[0]
    return ", ".join(items[:-1]) + ", and " + items[-1]


class _Household:
    def __init__(self, scene: Scene, version: str):
        self.version = check_version(version)
        self.places = {p.name: p for p in scene.places}
        self.contents = {p.name: list(p.contents) for p in scene.places}
        self.opened: set[str] = set()
        self.at: str | None = None
        self.holding: str | None = None

    def _put_command(self, obj: str, place: str) -> str:
        return f"put {obj} in/on {place}" if self.version == "2.1.1" else f"move {obj} to {place}"

    def _reachable(self, place: str) -> bool:
        return not self.places[place].openable or place in self.opened

    def _view(self, place: str) -> str:
        inside = _listing(self.contents[place])
        if not self.places[place].openable:
            return f"On the {place}, you see {inside}."
        if place not in self.opened:
            return f"The {place} is closed."
        return f"The {place} is open. In it, you see {inside}."

    def admissible(self) -> tuple[str, ...]:
        cmds = [f"go to {name}" for name in self.places if name != self.at]
        cmds += ["inventory", "look"] + (["help"] if self.version == "2.1.2" else [])
        if self.holding:
            cmds.append(f"examine {self.holding}")
        here = self.at
        if here is not None:
            cmds.append(f"examine {here}")
            if self.places[here].openable:
                cmds.append(f"{'close' if here in self.opened else 'open'} {here}")
            if self._reachable(here):
                if self.holding:
                    cmds.append(self._put_command(self.holding, here))
                else:
                    cmds += [
                        f"take {obj} from {here}" for obj in self.contents[here] if _kind_and_number(obj)[0] not in _FIXED_OBJECTS
                    ]
            verb = _TOOL_VERBS.get(_kind_and_number(here)[0])
            if verb and self.holding:
                cmds.append(f"{verb} {self.holding} with {here}")
            cmds += [f"use {obj}" for obj in self.contents[here] if obj.startswith("desklamp ")]
        return tuple(sorted(cmds))

    def opening(self, goal: str) -> str:
        around = _listing(list(self.places))
        return f"You are in the middle of a room. Looking quickly around you, you see {around}.\n\nYour task is to: {goal}."

    def play(self, action: str) -> str:
        """Apply an admissible ``action`` and return the game's answer."""
        verb, _, rest = action.partition(" ")
        if action == "inventory":
            return f"You are carrying: a {self.holding}." if self.holding else ("You are not carrying anything.")
        if action == "look":
            if self.at is None:
                return "You are in the middle of a room. Looking quickly around you, you see nothing."
            return f"You are facing the {self.at}. Next to it, you see nothing."
        if action.startswith("go to "):
            self.at = action[len("go to ") :]
            where = f"loc {self.places[self.at].loc}" if self.version == "2.1.1" else self.at
            return f"You arrive at {where}. {self._view(self.at)}"
        if verb == "open":
            self.opened.add(rest)
            return f"You open the {rest}. {self._view(rest)}"
        if verb == "close":
            self.opened.discard(rest)
            return f"You close the {rest}."
        if verb == "take":
            obj, _, place = rest.partition(" from ")
            self.contents[place].remove(obj)
            self.holding = obj
            return f"You pick up the {obj} from the {place}."
        if verb in ("put", "move"):
            assert self.holding is not None and self.at is not None
            obj, place = self.holding, self.at
            self.contents[place].append(obj)
            self.holding = None
            if self.version == "2.1.1":
                return f"You put the {obj} in/on the {place}."
            return f"You move the {obj} to the {place}."
        if verb in ("heat", "cool", "clean"):
            obj, _, place = rest.partition(" with ")
            return f"You {verb} the {obj} using the {place}."
        if verb == "use":
            return f"You turn on the {rest}."
        if verb == "examine":
            if rest in self.places:
                return self._view(rest)
            return f"There's nothing special about {rest}."
        raise ValueError(f"the household recorder does not model {action!r}")


def record(scene: Scene, actions: Sequence[str], *, name: str, split: str, task: str, version: str) -> Recording:
    """Play ``actions`` on ``scene``; the last action is the one that wins the game."""
    house = _Household(scene, version)
    start_valid = house.admissible()
    steps = []
    for i, action in enumerate(actions):
        if action not in house.admissible():
            raise ValueError(f"demonstration {name!r} step {i}: {action!r} is not admissible there")
        observation = house.play(action)
        steps.append(RecordedStep(action, observation, house.admissible(), i == len(actions) - 1))
    return Recording(
        name=name,
        split=split,
        task=task,
        observation=house.opening(scene.goal),
        goal=scene.goal,
        valid_actions=start_valid,
        steps=tuple(steps),
    )
