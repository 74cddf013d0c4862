"""The expert planner's problem and its single steps: roles, moves, and what each dish and soup needs next.

:class:`PlannerBase` holds what :class:`~.planner.Planner` knows about one problem (the recipe, the
objects chosen for its roles) and the one-action steps every job is built from (move, fetch, put
down); the parking rules (:mod:`.planner_parking`) and the policy (:mod:`.planner`) build on it.
"""

from __future__ import annotations

from .effects import base_name
from .goal import Goal
from .kitchen_view import View
from .recipe import PREP, Recipe, Soup, StackDish, analyze
from .roles import RoleChooser
from .state import Grounding, State


class PlannerBase:
    """One planning problem: a state, its goal and the roles chosen for goal variables."""

    def __init__(self, state: State, goal: Goal) -> None:
        self.goal = goal
        st = state
        item_names = {base_name(o) for o in st.objects["item"]}
        station_names = {base_name(o) for o in st.objects["station"]}
        self.recipe: Recipe = analyze(goal, item_names, station_names)
        self.kind_stations = {
            pred: [s for s in st.objects["station"] if (s,) in st.facts[pred]]
            for pred in ("istable", "isboard", "isstove", "isfryer", "issink")
        }
        self.actions = {a.name: a for a in st.domain.actions}
        self.dish_of: dict[int, StackDish] = {}
        for dish in self.recipe.dishes:
            for v in dish.all_vars():
                self.dish_of[v] = dish
        self.soup_of: dict[int, Soup] = {v: s for s in self.recipe.soups for v in s.ingredients}
        self.roles = RoleChooser(goal, self.recipe)
        self.assign: dict[int, str] = {}
        #: object -> the dish/soup item variable it plays
        self.role: dict[str, int] = {}
        #: station the held object was last taken from (parking avoids putting it straight back)
        self.picked_from: str | None = None
        #: the job (object or "soup") the policy committed to last
        self.focus: str | None = None
        #: why ``plan`` returned None
        self.failure = ""

    def needs(self, var: int, obj: str, view: View) -> list[str]:
        """The preparations ``obj`` still needs to play item variable ``var`` (see :meth:`RoleChooser.needs`)."""
        return self.roles.needs(var, obj, view)

    def ready(self, var: int, obj: str, view: View) -> bool:
        """Whether ``obj`` needs no more preparation to play item variable ``var``."""
        return self.roles.ready(var, obj, view)

    def choose_roles(self, view: View) -> bool:
        """Choose the objects for every goal variable from ``view``; False when some role can no longer be filled
        (the goal is out of reach)."""
        assign = self.roles.choose(view)
        if assign is None:
            return False
        self.assign = assign
        self.role = {o: v for v, o in assign.items() if v in self.dish_of or v in self.soup_of}
        return True

    def act(self, view: View, name: str, **args: str) -> Grounding | None:
        """The grounding of domain action ``name`` (robot = p1) if its preconditions hold now."""
        action = self.actions[name]
        binding = {"p1": view.robot, **args}
        if any(not view.st.holds(lit, binding) for lit in action.precons):
            return None
        params = [p for p, _ in action.params]
        text = action.description
        for p in params:
            text = text.replace("{" + p + "}", binding[p])
        return Grounding(action, tuple(binding[p] for p in params), text)

    def goto(self, view: View, station: str) -> Grounding | None:
        """The move to ``station``; None when the robot is already there (or cannot move now)."""
        if view.loc == station:
            return None
        return self.act(view, "move", s1=view.loc, s2=station)

    def fetch(self, view: View, obj: str) -> Grounding | None:
        """Step towards holding ``obj`` (an item on a station, or a container)."""
        if obj in view.container_at:
            station = view.container_at[obj]
            return self.goto(view, station) or self.act(view, "pick-up-container", c1=obj, s1=station)
        station, level = view.where[obj]
        move = self.goto(view, station)
        if move:
            return move
        stack = view.stacks[station]
        top = stack[-1]
        if len(stack) == 1:
            return self.act(view, "pick-up-item", i1=top, s1=station)
        return self.act(view, "unstack", i1=top, i2=stack[-2], s1=station)

    def put(self, view: View, station: str) -> Grounding | None:
        """Step towards putting the held item/container down on ``station``."""
        move = self.goto(view, station)
        if move:
            return move
        if view.held_container:
            return self.act(view, "place-container", c1=view.held_container, s1=station)
        item = view.held_item
        assert item is not None, "put() while holding nothing"
        if view.is_free(station):
            return self.act(view, "place-item", i1=item, s1=station)
        top = view.top(station)
        assert top is not None, f"stack on {station}, which holds nothing"
        return self.act(view, "stack", i1=item, i2=top, s1=station)

    def var_of(self, obj: str) -> int | None:
        """The goal variable ``obj`` plays; None for an object in no role."""
        return self.role.get(obj)

    def prep_target(self, var: int, obj: str, view: View) -> tuple[str, str] | None:
        """(next preparation, station predicate) for a role object; None when ready."""
        for prep in self.needs(var, obj, view):
            return prep, PREP[prep][0]
        return None

    def dish_order(self, dish: StackDish) -> list[int]:
        """The dish's variables in stacking order: the base, the ``atop`` chain upward from it, the loose
        members, and the top item last."""
        chain = [dish.base]
        below_of = {b: a for a, b in dish.below.items()}
        while chain[-1] in below_of:
            chain.append(below_of[chain[-1]])
        loose = [v for v in dish.members if v not in chain and v != dish.top]
        return chain + loose + ([dish.top] if dish.top is not None and dish.top not in chain else [])

    def dish_state(self, dish: StackDish, view: View) -> tuple[list[str], list[str]]:
        """(correct bottom part of the dish's table stack, items above it that must go)."""
        table = self.assign[dish.table]
        stack = view.stacks.get(table, [])
        fixed = {v: self.assign[v] for v in dish.all_vars() if v in self.assign}
        pins = self.roles.match_stack(dish, stack, view, fixed)
        good = stack[: len(pins)]
        return good, stack[len(pins) :]

    def dish_next(self, dish: StackDish, view: View) -> list[int]:
        """Variables that may go onto the dish next (given its correct bottom part)."""
        good, bad = self.dish_state(dish, view)
        if bad:
            return []
        if not good:
            return [dish.base]
        placed = {v for v in dish.all_vars() if self.assign[v] in good}
        last = next(v for v in dish.all_vars() if self.assign[v] == good[-1])
        chained = [a for a, b in dish.below.items() if b == last and a not in placed]
        if chained:
            return chained
        loose = [v for v in dish.members if v not in placed and v not in dish.below and v != dish.top]
        if loose:
            return loose
        if dish.top is not None and dish.top not in placed and dish.top not in dish.below:
            return [dish.top]
        return []

    def soup_pot(self, soup: Soup, view: View) -> str | None:
        """The pot holding (or being filled with) the soup's water, else an empty pot to use; None once the water
        has left the pot or no pot is free."""
        water = self.assign[soup.water]
        holder = view.meal_in.get(water)
        pots = [c for c in view.st.objects["container"] if view.true("ispot", c)]
        if holder in pots:
            return holder
        if water in view.st.types:
            return None  # the water left the pot
        filling = [c for c in pots if ("fill", c) in view.pending]
        if filling:
            return filling[0]
        empty = [c for c in pots if view.true("container_empty", c)]
        return empty[0] if empty else None

    def clear_station(self, view: View, station: str) -> Grounding | None:
        """Step towards emptying ``station``: fetch its top item, else its container; None when it is already free."""
        top = view.top(station)
        if top is not None:
            return self.fetch(view, top)
        if station in view.station_container:
            return self.fetch(view, view.station_container[station])
        return None
