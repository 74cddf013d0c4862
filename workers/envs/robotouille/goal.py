"""Goals: predicates over goal variables (numeric ids of object names), matched by search.

A goal entry such as ``item_on(bread#1, table#2)`` ranges over objects: equal ids denote the same
object and different ids different objects. An id used under two names means the first name that
declared it (the real engine's behaviour; in sync task 1 the "cheese" slot is the lettuce). A name
with no object at build time ranges over the objects it will create (``water1``, ``water2``...).

The real engine expands every injective assignment into a goal set up front (up to a quarter of a
million sets, minutes to build); here the goal holds iff a backtracking search finds one
assignment that makes every entry true. Same answers; ``count_assignments`` gives the number of
sets the real engine would build, for cross-checks.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from .data import DataFileError
from .effects import base_name

if TYPE_CHECKING:  # pragma: no cover
    from .state import State


@dataclass(frozen=True)
class GoalLiteral:
    """One goal entry: a predicate over goal ids, and whether it must hold or must not."""

    predicate: str
    vars: tuple[int, ...]  # goal ids
    is_true: bool = True


@dataclass(frozen=True)
class Goal:
    """A parsed goal: its entries and, per goal id, the object name it stands for and the objects it may be
    assigned (distinct ids take distinct objects)."""

    literals: tuple[GoalLiteral, ...]
    #: goal id -> object name it stands for (``bread``)
    var_names: dict[int, str]
    #: goal id -> candidate objects (fixed when the problem is built)
    domains: dict[int, tuple[str, ...]]

    def count_assignments(self) -> int:
        """Number of injective assignments (= the real engine's number of goal sets)."""
        per_name = Counter(self.var_names.values())
        total = 1
        for name, k in per_name.items():
            n = len(next(self.domains[v] for v, nm in self.var_names.items() if nm == name))
            total *= math.perm(n, k)
        return total

    def find_assignment(self, state: State, pinned: dict[int, str] | None = None) -> dict[int, str] | None:
        """An assignment making every literal true in ``state`` (None if there is none)."""
        return _search(self, state, dict(pinned or {}))

    def holds(self, state: State) -> bool:
        """Whether ``state`` satisfies the goal: some injective assignment makes every entry true."""
        return self.find_assignment(state) is not None


def parse_goal(raw: Any, state: State, source: str) -> Goal:
    """The goal of a problem JSON against its initial ``state``: each id takes the first name it appears under; a
    name with no object yet ranges over the objects it will create. DataFileError for a malformed goal or
    unknown predicate."""
    if not isinstance(raw, list):
        raise DataFileError(f"{source}: goal must be a list of entries")
    var_names: dict[int, str] = {}
    literals = []
    for entry in raw:
        pred = entry["predicate"]
        if pred not in state.facts:
            raise DataFileError(f"{source}: goal uses unknown predicate {pred!r}")
        ids = tuple(int(i) for i in entry["ids"])
        for name, i in zip(entry["args"], ids):
            var_names.setdefault(i, name)
        literals.append(GoalLiteral(pred, ids, bool(entry.get("is_true", True))))
    by_name: dict[str, list[str]] = {}
    for obj in state.types:
        by_name.setdefault(base_name(obj), []).append(obj)
    per_name = Counter(var_names.values())
    domains = {}
    for var, name in var_names.items():
        objs = by_name.get(name)
        if objs:
            # naming order within the object's type list
            objs = sorted(objs, key=lambda o: (state.types[o], state.index[o]))
            domains[var] = tuple(objs)
        else:
            domains[var] = tuple(f"{name}{k}" for k in range(1, per_name[name] + 1))
    return Goal(tuple(literals), var_names, domains)


def _search(goal: Goal, state: State, assignment: dict[int, str]) -> dict[int, str] | None:
    facts = state.facts
    # unary literals filter domains up front
    domains: dict[int, list[str]] = {}
    for var, dom in goal.domains.items():
        if var in assignment:
            domains[var] = [assignment.pop(var)]
        else:
            domains[var] = list(dom)
    rest = []
    for lit in goal.literals:
        if len(lit.vars) == 1:
            v = lit.vars[0]
            rows = facts[lit.predicate]
            domains[v] = [o for o in domains[v] if ((o,) in rows) == lit.is_true]
            if not domains[v]:
                return None
        else:
            rest.append(lit)
    # variable order: most constrained first, then by how many literals mention them
    mentions = Counter(v for lit in rest for v in set(lit.vars))
    order = sorted(domains, key=lambda v: (len(domains[v]), -mentions[v], v))
    position = {v: i for i, v in enumerate(order)}
    checks: list[list[GoalLiteral]] = [[] for _ in order]
    for lit in rest:
        checks[max(position[v] for v in lit.vars)].append(lit)

    chosen: dict[int, str] = {}
    used: set[str] = set()

    def extend(i: int) -> bool:
        if i == len(order):
            return True
        var = order[i]
        for obj in domains[var]:
            if obj in used:
                continue
            chosen[var] = obj
            ok = True
            for lit in checks[i]:
                if (tuple(chosen[v] for v in lit.vars) in facts[lit.predicate]) != lit.is_true:
                    ok = False
                    break
            if ok:
                used.add(obj)
                if extend(i + 1):
                    return True
                used.discard(obj)
        chosen.pop(var, None)
        return False

    return dict(chosen) if extend(0) else None
