"""Which object plays which goal role, chosen by estimated cost from the current state.

A goal names variables ("bread#1 on table#2"); several objects could fill each. The expert is
only as short as this choice is good: a table already holding a correct partial sandwich, a bread
already on a table, a lettuce already on a board or an item already held all save steps. Costs
count the actions still needed per role (transport = move, pick, move, put down); tables are
chosen jointly (injectively) with the dish parts already standing on them, then items per name.
A role no object can fill any more (an item added to the wrong soup, water poured out before it
boiled) makes the goal unreachable.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable

from .effects import base_name
from .goal import Goal
from .kitchen_view import View
from .recipe import PREP, PREP_ORDER, Recipe, Soup, StackDish

TRANSPORT = 4  # move to the object, pick it up, move to the target, put it down
INF = float("inf")


class RoleChooser:
    """Costs and the joint choice of objects for the variables of one goal."""

    def __init__(self, goal: Goal, recipe: Recipe) -> None:
        self.goal = goal
        self.recipe = recipe
        self.dish_of: dict[int, StackDish] = {}
        for dish in recipe.dishes:
            for v in dish.all_vars():
                self.dish_of[v] = dish
        self.soup_of: dict[int, Soup] = {v: s for s in recipe.soups for v in s.ingredients}

    def needs(self, var: int, obj: str, view: View) -> list[str]:
        """The preparations (cut, cook, fry, in that order) that ``obj`` still needs to fill item variable ``var``."""
        return [p for p in PREP_ORDER if p in self.recipe.needs.get(var, ()) and not view.true(p, obj)]

    def ready(self, var: int, obj: str, view: View) -> bool:
        """Whether ``obj`` already has every preparation item variable ``var`` needs."""
        return not self.needs(var, obj, view)

    def match_stack(self, dish: StackDish, stack: list[str], view: View, fixed: dict[int, str]) -> dict[int, str]:
        """Longest bottom part of ``stack`` that is a correct start of ``dish`` (var -> object)."""
        pins: dict[int, str] = {}
        if not stack:
            return pins
        names = self.goal.var_names

        def fits(var: int, obj: str) -> bool:
            if fixed.get(var, obj) != obj:
                return False
            return base_name(obj) == names[var] and self.ready(var, obj, view)

        if not fits(dish.base, stack[0]):
            return pins
        pins[dish.base] = stack[0]
        prev_var = dish.base
        for obj in stack[1:]:
            chained = [a for a, b in dish.below.items() if b == prev_var]
            options = chained or [v for v in dish.members if v not in pins and v not in dish.below]
            chosen = None
            for v in options:
                if v in pins or not fits(v, obj):
                    continue
                if v in dish.below and dish.below[v] != prev_var:
                    continue
                if v == dish.top and any(m not in pins for m in dish.members if m != v):
                    continue
                chosen = v
                break
            if chosen is None:
                break
            pins[chosen] = obj
            prev_var = chosen
        return pins

    def _dish_table_cost(self, dish: StackDish, table: str, view: View) -> tuple[float, dict[int, str]]:
        stack = view.stacks.get(table, [])
        extra = TRANSPORT if table in view.station_container else 0
        pins = self.match_stack(dish, stack, view, {})
        cost = extra + TRANSPORT * (len(stack) - len(pins)) + TRANSPORT * (len(dish.all_vars()) - len(pins))
        return cost, pins

    def _soup_table_cost(self, soup: Soup, table: str, view: View, bowl: str) -> float:
        if view.container_at.get(bowl) == table:
            return 0
        cost = TRANSPORT
        if table in view.station_container:
            cost += TRANSPORT
        return cost + TRANSPORT * len(view.stacks.get(table, []))

    def _item_cost(self, var: int, obj: str, view: View, water: dict[int, str]) -> float:
        added = view.added.get(obj)
        soup = self.soup_of.get(var)
        if added is not None:
            # an added item cannot be taken out or prepared any more
            usable = soup is not None and water.get(soup.water) == added and not self.needs(var, obj, view)
            return 0 if usable else INF
        cost = 0.0
        station, level = view.where.get(obj, (None, 0))
        held = view.held_item == obj
        if station is not None:
            cost += TRANSPORT * (len(view.stacks[station]) - 1 - level)
        for prep in self.needs(var, obj, view):
            station_pred = PREP[prep][0]
            if not view.st.facts[station_pred]:
                return INF  # no such station in this kitchen
            in_place = station is not None and level == 0 and view.true(station_pred, station)
            if prep == "iscut":
                if not view.true("iscuttable", obj):
                    return INF
                count = next((e.counter for e in view.st.effects if e.spec.kind == "repetitive" and e.arg == obj), 0)
                cost += max(3 - count, 1) + (0 if in_place else TRANSPORT)
            elif prep == "iscooked":
                if not view.true("iscookable", obj):
                    return INF
                if ("iscooked", obj) in view.pending:
                    cost += 1
                else:
                    cost += 1 + (0 if in_place else TRANSPORT)
            else:
                fryable = view.true("isfryable", obj) or (
                    view.true("isfryableifcut", obj) and "iscut" in self.needs(var, obj, view)
                )
                if not fryable:
                    return INF
                cost += 1 + (0 if in_place else TRANSPORT)
        cost += TRANSPORT // 2 if held else TRANSPORT
        return cost

    def choose(self, view: View) -> dict[int, str] | None:
        """Goal variable -> object for every variable; None when some role has no usable object."""
        fixed, water = self._soup_roles(view)
        if not self._choose_tables(view, fixed):
            return None
        if not self._choose_items(view, fixed, water):
            return None
        if not self._soups_still_possible(view, fixed, water):
            return None
        return fixed

    def _soup_roles(self, view: View) -> tuple[dict[int, str], dict[int, str]]:
        """(roles fixed so far, each soup's water): the water that exists already (else the first of its
        domain) and the bowl that holds it (else the first bowl)."""
        goal = self.goal
        fixed: dict[int, str] = {}
        water: dict[int, str] = {}
        for soup in self.recipe.soups:
            dom = goal.domains[soup.water]
            existing = [w for w in dom if w in view.st.types]
            water[soup.water] = existing[0] if existing else next(w for w in dom)
            fixed[soup.water] = water[soup.water]
            bowls = list(goal.domains[soup.bowl])
            holder = view.meal_in.get(water[soup.water])
            fixed[soup.bowl] = holder if holder in bowls else bowls[0]
        return fixed, water

    def _choose_tables(self, view: View, fixed: dict[int, str]) -> bool:
        """Every dish/soup table variable, injective, cheapest in total (with the item roles each dish
        table's cost assumed) into ``fixed``; False when no assignment exists."""
        goal, recipe = self.goal, self.recipe
        table_vars = recipe.table_vars
        costs: dict[tuple[int, str], tuple[float, dict[int, str]]] = {}
        for dish in recipe.dishes:
            for t in goal.domains[dish.table]:
                costs[(dish.table, t)] = self._dish_table_cost(dish, t, view)
        for soup in recipe.soups:
            if soup.table is not None:
                for t in goal.domains[soup.table]:
                    costs[(soup.table, t)] = (self._soup_table_cost(soup, t, view, fixed[soup.bowl]), {})
        best: tuple[float, dict[int, str]] | None = None
        for combo in itertools.permutations(_union(goal.domains[v] for v in table_vars), len(table_vars)):
            if any(t not in goal.domains[v] for v, t in zip(table_vars, combo)):
                continue
            total = sum(costs[(v, t)][0] for v, t in zip(table_vars, combo))
            if best is None or total < best[0]:
                chosen = dict(zip(table_vars, combo))
                best = (total, chosen)
        if table_vars and best is None:
            return False
        if best is not None:
            fixed.update(best[1])
            for v, t in best[1].items():
                fixed.update(costs[(v, t)][1])
        return True

    def _choose_items(self, view: View, fixed: dict[int, str], water: dict[int, str]) -> bool:
        """The remaining item variables, per object name the cheapest injective choice, into ``fixed``;
        False when some name has no usable choice."""
        goal = self.goal
        taken = set(fixed.values())
        by_name: dict[str, list[int]] = {}
        for v in self.recipe.item_vars:
            if v not in fixed:
                by_name.setdefault(goal.var_names[v], []).append(v)
        for _name, vars_ in by_name.items():
            objs = [o for o in goal.domains[vars_[0]] if o not in taken]
            options = None
            for combo in itertools.permutations(objs, len(vars_)):
                total = sum(self._item_cost(v, o, view, water) for v, o in zip(vars_, combo))
                if options is None or total < options[0]:
                    options = (total, combo)
            if options is None or options[0] == INF:
                return False
            fixed.update(zip(vars_, options[1]))
            taken.update(options[1])
        return True

    def _soups_still_possible(self, view: View, fixed: dict[int, str], water: dict[int, str]) -> bool:
        """False when a soup was poured out before it was boiled or had every ingredient."""
        for soup in self.recipe.soups:
            w = water[soup.water]
            holder = view.meal_in.get(w)
            if holder is not None and not view.true("ispot", holder):
                # poured out: nothing can be boiled or added any more
                if soup.boil and not view.true("isboiling", w):
                    return False
                if any(view.added.get(fixed[v]) != w for v in soup.ingredients):
                    return False
        return True


def _union(groups: Iterable[Iterable[str]]) -> list[str]:
    """The objects of every group, each once, in first-seen order."""
    out: list[str] = []
    for g in groups:
        for x in g:
            if x not in out:
                out.append(x)
    return out
