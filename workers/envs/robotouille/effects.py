"""Special effects in flight: delayed (timers), repetitive (counters), conditional, creation, ...

An action's special effects are templates (``domain.EffectSpec``); taking the action binds them to
the action's objects and registers them on the state, where they are updated once *actively* (by
the action itself) and then once *passively* per step until they complete. Equality ignores the
counters so that re-issuing an action (the 2nd and 3rd cut) advances the effect already running
instead of starting another one.

Timing, as observed on the real engine:
- delayed: counts passive updates only and fires when its counter reaches ``time + 1`` (the
  action's own step is the first tick: cook at step t -> cooked after step t+3 with time 3);
- repetitive: counts active updates only and fires on the ``n``-th one (cut x3);
- conditional: while its conditions hold, applies its effects and updates its nested effects
  (with the same active flag); it completes when all nested effects have (at once if none);
- creation: creates ``<name><k>``, binds it and applies its effects; deletion removes its object;
  immediate: applies its effects. These three complete on their first update.

Taking an item (or pot) off its station while an effect runs, and putting it back
---------------------------------------------------------------------------------
The real engine (release c8236a2e; trajectory T7, and its ``ConditionalEffect.update``) checks a
conditional effect's conditions at *every* update, active or passive. Our reading, implemented here
for every conditional effect of any domain (nothing is special-cased for cook):

- Removal. When one of its conditions does not hold (cook, fry: ``item_on(i1, s1)``; fill pot,
  boil: ``container_at(c1, s1)``), the update sets each of the conditional's *own* effects to its
  negation and returns: the nested effects are not updated, so their timers do not tick that step.
  Cook: ``iscooking`` becomes false (the observation shows the patty held, not cooking). Fry, fill
  pot and boil have no own effects, so only their timers stop. The effect is neither completed nor
  reset: it stays registered with its nested counters as they were, and repeats the negation at
  every update while its conditions fail (it is never dropped if they never hold again).
- Return. The effect is still registered, so as soon as its conditions hold again - already at the
  passive update of the step that puts the item back on the *same* station (the conditions name
  the station the action was taken on) - it re-applies its effects (``iscooking`` true again) and
  its nested effects tick on from their saved counters: **the timer pauses; it neither restarts
  nor stays done.** T7: Cook at step 24 (timer 1/4), Pick up at 25 (timer 1, not cooking), Do
  nothing at 26 (timer 1), Place back at 27 (timer 2, cooking), 28 (timer 3), cooked after 29:
  two steps late, the two steps the patty spent off the stove.
- Re-issuing the action on the same station finds the equal effect already registered (equality
  ignores counters) and updates that one actively: nothing restarts (for cook the precondition
  ``not iscooking`` normally forbids it anyway, since the put-back step already set ``iscooking``).
  On *another* station the conditions differ, so a new effect starts from zero while the old one
  stays registered and paused, negating its effects at each of its updates (effects update in
  registration order, so the newer one's ``iscooking`` wins), and resumes if the item ever returns
  to its first station.
- Both directions go through ordinary updates, so the timer-skip quirk (see ``state.State.apply``)
  applies to them too: an effect that misses its passive update in the pickup step leaves the item
  shown cooking for that step, and one that misses it in the put-back step shows it not cooking.

The other kinds under the same reading:
- delayed: only ticks when updated; nested in a conditional it is paused by removal and resumes on
  return as above (its counter is kept). A top-level delayed effect (none in the benchmark domain)
  would not care where its object is.
- repetitive (cut): top level, not conditional; it counts the active updates of the one effect
  bound to the item (its equality key names only the item), so taking the item off the board and
  cutting again later, on any board, continues the count: it fires on the 3rd cut whatever happens
  in between. The cut's conditional (``isfryable`` once cut, for fryable-if-cut items) has no nested
  effects; while its conditions fail it sets ``isfryable`` false at each update.
- creation (the water of a filled pot): nested in the fill's delayed effect, it fires only when
  that timer does, i.e. with the pot on its sink; removal pauses it, return resumes it.
- deletion and immediate: complete on their first update; nothing is left in flight to pause.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from typing import Protocol

from .domain import EffectSpec, Literal


class EffectTarget(Protocol):
    """What an effect reads and changes on the engine state (``state.State`` is one).

    Declared here rather than importing ``State``: the state module imports this one to
    register effects, so naming the few methods an effect uses keeps the two modules out of
    an import cycle.
    """

    def holds(self, lit: Literal, binding: dict[str, str]) -> bool: ...

    def apply_literals(self, literals: Iterable[Literal], binding: dict[str, str], negate: bool = False) -> None: ...

    def create_object(self, name: str, obj_type: str) -> str: ...

    def delete_object(self, name: str) -> None: ...


_TRAILING_DIGITS = re.compile(r"\d+$")


def base_name(obj: str) -> str:
    """``chicken12`` -> ``chicken`` (the name the problem file used for the object)."""
    return _TRAILING_DIGITS.sub("", obj)


def _params_of(spec: EffectSpec, out: set[str]) -> set[str]:
    out.add(spec.param)
    for lit in spec.fx:
        out.update(lit.params)
    for lit in spec.conditions:
        out.update(lit.params)
    for nested in spec.nested:
        _params_of(nested, out)
    if spec.created is not None:
        out.discard(spec.created.param)
    return out


class ActiveEffect:
    """One bound special effect (with its nested effects) registered on a state."""

    __slots__ = ("spec", "arg", "binding", "nested", "completed", "counter", "goal", "key")

    def __init__(self, spec: EffectSpec, binding: dict[str, str], config: dict) -> None:
        self.spec = spec
        self.binding = binding
        self.arg = binding[spec.param]
        self.completed = False
        self.counter = 0
        self.goal = 0
        if spec.kind == "delayed":
            self.goal = _config_value(config, "cook_time", self.arg) + 1
        elif spec.kind == "repetitive":
            self.goal = _config_value(config, "num_cuts", self.arg)
        self.nested = [ActiveEffect(n, binding, config) for n in spec.nested]
        used = sorted(_params_of(spec, set()))
        self.key = (spec, tuple((p, binding.get(p)) for p in used))

    # equality ignores counters and completion, as the real engine's does
    def __eq__(self, other: object) -> bool:
        return isinstance(other, ActiveEffect) and self.key == other.key

    def __hash__(self) -> int:
        return hash(self.key)

    def copy(self) -> ActiveEffect:
        new = object.__new__(ActiveEffect)
        new.spec = self.spec
        new.arg = self.arg
        new.binding = self.binding
        new.completed = self.completed
        new.counter = self.counter
        new.goal = self.goal
        new.key = self.key
        new.nested = [n.copy() for n in self.nested]
        return new

    def update(self, state: EffectTarget, active: bool) -> None:
        if self.completed:
            return
        kind = self.spec.kind
        if kind == "conditional":
            if all(state.holds(lit, self.binding) for lit in self.spec.conditions):
                state.apply_literals(self.spec.fx, self.binding)
                for nested in self.nested:
                    nested.update(state, active)
                self.completed = all(n.completed for n in self.nested)
            else:
                # conditions no longer hold (item taken off its station): undo the effects and
                # leave the nested ones untouched, so their timers pause (see module docstring)
                state.apply_literals(self.spec.fx, self.binding, negate=True)
            return
        if kind == "delayed":
            if not active:
                self.counter += 1
            if self.counter == self.goal:
                self._fire(state, self.binding, active)
            return
        if kind == "repetitive":
            if active:
                self.counter += 1
            if self.counter == self.goal:
                self._fire(state, self.binding, active)
            return
        if kind == "creation":
            created = self.spec.created
            assert created is not None
            name = state.create_object(created.name, created.type)
            binding = dict(self.binding)
            binding[created.param] = name
            for nested in self.nested:
                nested.binding = binding
            self._fire(state, binding, active)
            return
        if kind == "deletion":
            state.apply_literals(self.spec.fx, self.binding)
            state.delete_object(self.arg)
            for nested in self.nested:
                nested.update(state, active)
            self.completed = True
            return
        # immediate
        self._fire(state, self.binding, active)

    def _fire(self, state: EffectTarget, binding: dict[str, str], active: bool) -> None:
        state.apply_literals(self.spec.fx, binding)
        for nested in self.nested:
            nested.update(state, active)
        self.completed = True

    def describe(self) -> dict:
        """The effect in the shape the recorded trajectories list it (for replay checks)."""
        kind = self.spec.kind
        out: dict = {
            "type": kind.capitalize() + "Effect",
            "arg": self.arg,
            "param": self.spec.param,
            "completed": self.completed,
        }
        if kind == "delayed":
            out["current_time"] = self.counter
            out["goal_time"] = self.goal
        elif kind == "repetitive":
            out["current_repetitions"] = self.counter
            out["goal_repetitions"] = self.goal
        if self.nested:
            out["nested"] = [n.describe() for n in self.nested]
        return out


def _config_value(config: dict, key: str, arg: str) -> int:
    table = config.get(key) or {}
    name = base_name(arg)
    if name in table:
        return int(table[name])
    return int(table.get("default", 3))
