"""A planner's view of an engine state: who holds what, stacks per station, timers in flight.

The engine stores flat facts; the expert planner needs them organised (the stack on each station,
where each item is, which meal is in which container) and needs to know which delayed results are
on their way, where their subject must stay, and whether they are progressing or paused.
"""

from __future__ import annotations

from dataclasses import dataclass

from .effects import ActiveEffect
from .state import State


@dataclass
class Pending:
    """A delayed result in flight: where its subject must stay, ticks left, and whether it is
    progressing (its conditions hold now) or paused (the subject was taken away)."""

    station: str | None
    remaining: int
    progressing: bool = True


class View:
    """The facts of a state reorganised for the policy (who holds what, stacks per station)."""

    def __init__(self, st: State) -> None:
        f = st.facts
        self.st = st
        self.robot = st.objects["player"][0]
        self.loc = next(s for p, s in f["loc"] if p == self.robot)
        self.held_item = next((i for p, i in f["has_item"] if p == self.robot), None)
        self.held_container = next((c for p, c in f["has_container"] if p == self.robot), None)
        above = {b: a for a, b in f["atop"]}
        self.stacks: dict[str, list[str]] = {}
        self.where: dict[str, tuple[str, int]] = {}
        for item, station in f["item_on"]:
            stack = [item]
            while stack[-1] in above:
                stack.append(above[stack[-1]])
            self.stacks[station] = stack
            for k, x in enumerate(stack):
                self.where[x] = (station, k)
        self.container_at = {c: s for c, s in f["container_at"]}
        self.station_container = {s: c for c, s in f["container_at"]}
        self.meal_in = {m: c for m, c in f["in"]}
        self.container_meal = {c: m for m, c in f["in"]}
        self.added = {i: m for i, m in f["addedto"]}
        self.pending: dict[tuple[str, str], Pending] = {}
        for effect in st.effects:
            self._scan(effect, None)

    def _scan(self, effect: ActiveEffect, station: str | None, active: bool = True) -> None:
        if effect.completed:
            return
        kind = effect.spec.kind
        if kind == "conditional":
            active = active and all(self.st.holds(c, effect.binding) for c in effect.spec.conditions)
            for lit in effect.spec.conditions:
                if lit.predicate in ("item_on", "container_at") and lit.is_true:
                    station = effect.binding[lit.params[1]]
        if kind == "delayed":
            remaining = effect.goal - effect.counter
            for lit in effect.spec.fx:
                if lit.is_true:
                    args = tuple(effect.binding[p] for p in lit.params)
                    self.pending[(lit.predicate, args[0])] = Pending(station, remaining, active)
            for nested in effect.nested:
                if nested.spec.kind == "creation":
                    self.pending[("fill", effect.arg)] = Pending(station, remaining, active)
            return
        for nested in effect.nested:
            self._scan(nested, station, active)

    def true(self, pred: str, *args: str) -> bool:
        """Whether the fact ``pred(*args)`` holds in the state."""
        return args in self.st.facts[pred]

    def top(self, station: str) -> str | None:
        """The object on top of ``station``'s stack; None when nothing is on it."""
        stack = self.stacks.get(station)
        return stack[-1] if stack else None

    def is_free(self, station: str) -> bool:
        """Whether ``station`` holds nothing (``station_empty``)."""
        return self.true("station_empty", station)


def busy(obj: str, view: View) -> bool:
    """True while a timer on ``obj`` is running (taking it away would pause it)."""
    return any(key[1] == obj and p.progressing for key, p in view.pending.items())
