"""The engine state: objects, true facts, special effects in flight; valid actions and stepping.

Semantics follow the real engine (release c8236a2e) as documented in the data README:
- a grounding of an action is valid iff every precondition has exactly its truth value (a fact
  that is not stored is false); groundings come in domain action order, then in product order
  over the typed object lists (objects in naming order), skipping groundings that repeat an object;
- a step applies the immediate effects, registers each special effect (an equal one already in
  flight is reused) and updates it actively, then updates every effect passively, dropping the
  completed ones *while iterating*: like the real engine, the effect right after a dropped one is
  not updated in that step (the "timer-skip" quirk);
- a conditional effect whose conditions stop holding (its item taken off the station) sets its own
  effects to their negation and pauses its nested timers until they hold again (``effects``).

Facts are stored per predicate as sets of argument tuples so that grounding is a join over the
positive preconditions instead of a scan of every object combination (fast steps and clones).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

from .domain import ActionDef, Domain, Literal
from .effects import ActiveEffect, base_name


@dataclass(frozen=True)
class Grounding:
    """One valid action: its definition, arguments in parameter order, and its text."""

    action: ActionDef
    args: tuple[str, ...]
    text: str


class State:
    """Mutable kitchen state. ``clone()`` is cheap enough for planning by simulation."""

    __slots__ = ("domain", "config", "objects", "types", "index", "facts", "effects", "_valid")

    def __init__(self, domain: Domain, config: dict) -> None:
        self.domain = domain
        self.config = config
        #: object names per type, in naming order (product order of groundings)
        self.objects: dict[str, list[str]] = {t: [] for t in domain.object_types}
        self.types: dict[str, str] = {}
        self.index: dict[str, int] = {}
        self.facts: dict[str, set[tuple[str, ...]]] = {p.name: set() for p in domain.predicates}
        self.effects: list[ActiveEffect] = []
        self._valid: list[Grounding] | None = None

    # ----------------------------------------------------------------- objects
    def add_object(self, name: str, obj_type: str) -> None:
        if obj_type not in self.objects:
            raise ValueError(f"unknown object type {obj_type!r} for {name!r}")
        if name in self.types:
            raise ValueError(f"duplicate object name {name!r}")
        self.index[name] = len(self.objects[obj_type])
        self.objects[obj_type].append(name)
        self.types[name] = obj_type

    def create_object(self, name: str, obj_type: str) -> str:
        """A new object ``<name><k>``, k one past the highest number used by ``name``."""
        used = [int(o[len(name) :]) for o in self.types if base_name(o) == name and o[len(name) :].isdigit()]
        new = f"{name}{max(used, default=0) + 1}"
        self.add_object(new, obj_type)
        self._valid = None
        return new

    def delete_object(self, name: str) -> None:
        obj_type = self.types.pop(name)
        self.objects[obj_type].remove(name)
        for i, o in enumerate(self.objects[obj_type]):
            self.index[o] = i
        del self.index[name]
        for _pred, rows in self.facts.items():
            dead = {r for r in rows if name in r}
            if dead:
                rows -= dead
        self._valid = None

    # ------------------------------------------------------------------- facts
    def holds(self, lit: Literal, binding: dict[str, str]) -> bool:
        args = tuple(binding[p] for p in lit.params)
        return (args in self.facts[lit.predicate]) == lit.is_true

    def apply_literals(self, literals, binding: dict[str, str], negate: bool = False) -> None:
        """Set each literal to its truth value (to the opposite one with ``negate``)."""
        for lit in literals:
            args = tuple(binding[p] for p in lit.params)
            if lit.is_true != negate:
                self.facts[lit.predicate].add(args)
            else:
                self.facts[lit.predicate].discard(args)
        self._valid = None

    def is_true(self, predicate: str, *args: str) -> bool:
        return args in self.facts[predicate]

    def true_facts(self) -> Iterator[tuple[str, tuple[str, ...]]]:
        for pred, rows in self.facts.items():
            for row in rows:
                yield pred, row

    def clone(self) -> State:
        new = object.__new__(State)
        new.domain = self.domain
        new.config = self.config
        new.objects = {t: list(v) for t, v in self.objects.items()}
        new.types = dict(self.types)
        new.index = dict(self.index)
        new.facts = {p: set(v) for p, v in self.facts.items()}
        new.effects = [e.copy() for e in self.effects]
        new._valid = self._valid
        return new

    # ----------------------------------------------------------- valid actions
    def valid_groundings(self) -> list[Grounding]:
        if self._valid is None:
            self._valid = [g for action in self.domain.actions for g in self._ground(action)]
        return self._valid

    def valid_actions(self) -> tuple[str, ...]:
        return tuple(g.text for g in self.valid_groundings())

    def _ground(self, action: ActionDef) -> list[Grounding]:
        params = [p for p, _ in action.params]
        positives = [lit for lit in action.precons if lit.is_true]
        negatives = [lit for lit in action.precons if not lit.is_true]
        found: list[dict[str, str]] = []

        def join(i: int, binding: dict[str, str]) -> None:
            if i == len(positives):
                found.append(dict(binding))
                return
            lit = positives[i]
            rows = self.facts[lit.predicate]
            bound = [(k, binding[p]) for k, p in enumerate(lit.params) if p in binding]
            if len(bound) == len(lit.params):
                if tuple(binding[p] for p in lit.params) in rows:
                    join(i + 1, binding)
                return
            for row in rows:
                if all(row[k] == v for k, v in bound):
                    new = dict(binding)
                    ok = True
                    for k, p in enumerate(lit.params):
                        if p in new:
                            if new[p] != row[k]:
                                ok = False
                                break
                        else:
                            new[p] = row[k]
                    if ok:
                        join(i + 1, new)

        join(0, {})
        # parameters no positive precondition binds range over their whole type
        types = dict(action.params)
        free = [p for p in params if not positives or all(p not in lit.params for lit in positives)]
        for p in free:
            found = [dict(b, **{p: o}) for b in found for o in self.objects[types[p]]]
        out = []
        for binding in found:
            args = tuple(binding[p] for p in params)
            if len(set(args)) != len(args):
                continue
            if any(not self.holds(lit, binding) for lit in negatives):
                continue
            out.append((tuple(self.index[a] for a in args), args, binding))
        out.sort(key=lambda r: r[0])
        result = []
        for _, args, binding in out:
            text = action.description
            for p in params:
                text = text.replace("{" + p + "}", binding[p])
            result.append(Grounding(action, args, text))
        return result

    # -------------------------------------------------------------------- step
    def apply(self, grounding: Grounding) -> None:
        """Take one valid action (the caller checked validity)."""
        action = grounding.action
        binding = dict(zip((p for p, _ in action.params), grounding.args))
        self.apply_literals(action.immediate_fx, binding)
        for spec in action.sfx:
            effect = ActiveEffect(spec, binding, self.config)
            try:
                effect = self.effects[self.effects.index(effect)]
            except ValueError:
                self.effects.append(effect)
            effect.update(self, active=True)
        # passive updates; dropping while iterating skips the next effect (real-engine quirk)
        effects = self.effects
        i = 0
        while i < len(effects):
            effect = effects[i]
            effect.update(self, active=False)
            if effect.completed:
                del effects[effects.index(effect)]
            i += 1
        self._valid = None

    # ------------------------------------------------------------- observation
    def describe_objects(self) -> str:
        """One block per object: ``<Type> <name>:`` then every true sentence that mentions it."""
        dom = self.domain
        lines: dict[str, list[tuple[int, tuple[int, ...], str]]] = {o: [] for o in self.types}
        index = self.index
        for pred, rows in self.facts.items():
            if not rows:
                continue
            pdef = dom.predicate(pred)
            order = dom.predicate_index(pred)
            for row in rows:
                if len(set(row)) != len(row):
                    continue
                key = tuple(index[a] for a in row)
                for k, obj in enumerate(row):
                    lines[obj].append((order, key, pdef.sentences[k].format(*row)))
        blocks = []
        for obj_type in dom.object_types:
            label = obj_type.capitalize()
            for obj in self.objects[obj_type]:
                entries = sorted(lines[obj])
                blocks.append("\n".join([f"{label} {obj}:"] + [e[2] for e in entries]))
        return "\n\n".join(blocks)

    def observation(self, goal_description: str) -> str:
        actions = "\n".join(self.valid_actions())
        return f"{self.describe_objects()}\n\nValid Actions:\n{actions}\n\nGoal: {goal_description}"
