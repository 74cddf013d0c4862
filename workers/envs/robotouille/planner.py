"""Expert planner: a cooking policy simulated on a copy of the engine state.

Used by the offline expert model (a test double) and for solvability checks, so it must solve any
instance from any reachable state, quickly, with plans close to the benchmark's optimal counts.
Rather than a blind search over primitive actions, it:

1. reads the goal as dishes and soups (``recipe.analyze``);
2. picks which objects play which goal roles, by estimated cost from the *current* state (a table
   already holding a good partial sandwich, a lettuce already on a board, a bread already held...);
3. runs a priority policy on a cloned state until the goal holds: start slow processes first
   (fill the pot, cook, cut-then-fry, boil), lay dish bases, cut, then assemble; park anything in
   the way; while timers run, walk to where the next result appears or ``Do nothing``.

Simulating on the engine itself keeps every emitted action valid and every timer (including the
real engine's timer-skip quirk) exact. ``plan`` returns None when the goal is out of reach (e.g. the
soup's water was poured into the bowl before it boiled).
"""

from __future__ import annotations

from .goal import Goal
from .kitchen_view import View, busy
from .planner_parking import ParkingPlanner
from .recipe import PREP, Soup, UnsupportedGoal
from .state import Grounding, State


class Planner(ParkingPlanner):
    """One planning problem and its policy: the jobs tried in priority order until the goal holds.

    The problem and its one-action steps live in :class:`~.planner_steps.PlannerBase`, where to put
    things down in :class:`~.planner_parking.ParkingPlanner`.
    """

    def plan(self, state: State, limit: int) -> list[str] | None:
        """The actions that reach the goal from ``state`` (simulated on a clone; ``state`` is untouched), [] when
        it already holds; None when roles cannot be filled, the policy gets stuck or ``limit`` actions are not
        enough (``failure`` says which)."""
        sim = state.clone()
        if self.goal.holds(sim):
            return []
        if not self.choose_roles(View(sim)):
            self.failure = "unreachable: some goal role has no usable object"
            return None
        actions: list[str] = []
        for _ in range(limit):
            view = View(sim)
            grounding = self.next_action(view)
            if grounding is None:
                self.failure = f"stuck after {len(actions)} actions"
                return None
            if grounding.action.name in ("pick-up-item", "unstack", "pick-up-container"):
                self.picked_from = grounding.args[-1]
            sim.apply(grounding)
            actions.append(grounding.text)
            if self.goal.holds(sim):
                return actions
        self.failure = f"no plan within {limit} actions"
        return None

    def next_action(self, view: View) -> Grounding | None:
        """The policy's next action: deal with what the robot holds, else the first of start slow work, lay
        bases, cut, assemble, pour, wait that has something to do; None when stuck."""
        if view.held_item is not None:
            return self.handle_held_item(view)
        if view.held_container is not None:
            return self.handle_held_container(view)
        for step in (self.start_slow, self.lay_bases, self.cut_jobs, self.assemble, self.pour, self.wait):
            action = step(view)
            if action is not None:
                return action
        return None

    def handle_held_item(self, view: View) -> Grounding | None:
        """Where the held item goes: to its next preparation station, onto its dish or into its soup when it is
        next, else parked."""
        obj = view.held_item
        assert obj is not None
        var = self.var_of(obj)
        if var is not None:
            target = self.prep_target(var, obj, view)
            if target is not None:
                prep, pred = target
                pending = view.pending.get((prep, obj))
                if pending is not None and pending.station is not None:
                    if view.is_free(pending.station):
                        return self.put(view, pending.station)
                    return self.park(view)
                station = self.free_station(view, pred)
                if station is not None:
                    return self.put(view, station)
                return self.park(view)
            dish = self.dish_of.get(var)
            if dish is not None and var in self.dish_next(dish, view):
                table = self.assign[dish.table]
                if table not in view.station_container:
                    return self.put(view, table)
            soup = self.soup_of.get(var)
            if soup is not None:
                pot = self.soup_pot(soup, view)
                water = self.assign[soup.water]
                if pot is not None and view.meal_in.get(water) == pot and pot in view.container_at:
                    station = view.container_at[pot]
                    return self.goto(view, station) or self.act(view, "add-to", i1=obj, c1=pot, m1=water, s1=station)
        return self.park(view)

    def handle_held_container(self, view: View) -> Grounding | None:
        """Where a held container goes: the soup's pot onto a sink (to fill) or a stove (to boil), or poured into its bowl; the bowl onto its table; else parked."""
        c = view.held_container
        assert c is not None
        for soup in self.recipe.soups:
            water = self.assign[soup.water]
            if c == self.soup_pot(soup, view):
                fill = view.pending.get(("fill", c))
                boil = view.pending.get(("isboiling", water))
                if water not in view.st.types:
                    station = fill.station if fill else self.free_station(view, "issink")
                    if station is not None and view.is_free(station):
                        return self.put(view, station)
                    return self.park(view)
                if soup.boil and not view.true("isboiling", water):
                    station = boil.station if boil else self.free_station(view, "isstove")
                    if station is not None and view.is_free(station):
                        return self.put(view, station)
                    return self.park(view)
                bowl = self.assign[soup.bowl]
                table = self.assign[soup.table] if soup.table is not None else None
                added = all(view.added.get(self.assign[i]) == water for i in soup.ingredients)
                bowl_at = view.container_at.get(bowl)
                if added and bowl_at is not None and (table is None or bowl_at == table) and view.true("container_empty", bowl):
                    return self.goto(view, bowl_at) or self.act(view, "fill-bowl", c1=bowl, c2=c, m1=water, s1=bowl_at)
                return self.park(view)
            if c == self.assign[soup.bowl] and soup.table is not None:
                table = self.assign[soup.table]
                if view.is_free(table):
                    return self.put(view, table)
                return self.park(view)
        return self.park(view)

    def prep_step(self, var: int, obj: str, view: View) -> Grounding | None:
        """Next action preparing ``obj``: act on it where it is, or go and get it."""
        target = self.prep_target(var, obj, view)
        if target is None:
            return None
        prep, pred = target
        if obj in view.added or obj not in view.where:
            return None
        if (prep, obj) in view.pending:
            pending = view.pending[(prep, obj)]
            station, _ = view.where[obj]
            if pending.station == station:
                return None  # in progress
            if pending.station is not None and not view.is_free(pending.station):
                return self.clear_station(view, pending.station)
            return self.fetch(view, obj)
        station, level = view.where[obj]
        stack = view.stacks[station]
        if view.true(pred, station) and level == 0:
            if len(stack) > 1:
                return self.fetch(view, stack[-1])
            if prep == "iscooked" and view.true("iscooking", obj):
                return None
            action_name = PREP[prep][1]
            return self.goto(view, station) or self.act(view, action_name, i1=obj, s1=station)
        if self.free_station(view, pred) is None:
            return self.clear_one(view, pred)
        return self.fetch(view, obj)

    def _closest(self, options: list[tuple[str, Grounding | None]], view: View) -> Grounding | None:
        """Pick among jobs (in priority order).

        Stick with the job chosen last time if it is still open (no thrashing between two jobs
        that each undo the other's parking); else prefer a job whose next action works on its
        own object where the robot stands (no move, no clearing); else the first job.
        """
        best = None
        best_rank = None
        for index, (key, action) in enumerate(options):
            if action is None:
                continue
            if key == self.focus:
                return action
            direct = action.action.name != "move" and (key == "soup" or key in action.args)
            rank = (0 if direct else 1, index)
            if best_rank is None or rank < best_rank:
                best, best_rank = (key, action), rank
        if best is None:
            return None
        self.focus = best[0]
        return best[1]

    def start_slow(self, view: View) -> Grounding | None:
        """A step towards starting a slow process (a soup, cooking, frying: they run on their own once started),
        the job picked by :meth:`_closest`."""
        options: list[tuple[str, Grounding | None]] = []
        for soup in self.recipe.soups:
            options.append(("soup", self.soup_step(soup, view)))
        for var in self.recipe.item_vars:
            obj = self.assign[var]
            needs = self.needs(var, obj, view)
            if "iscooked" in needs or "isfried" in needs:
                options.append((obj, self.prep_step(var, obj, view)))
        return self._closest(options, view)

    def soup_step(self, soup: Soup, view: View) -> Grounding | None:
        """Next action for the soup's water: fill the pot, then boil it."""
        water = self.assign[soup.water]
        pot = self.soup_pot(soup, view)
        if pot is None:
            return None
        station = view.container_at.get(pot)
        if water not in view.st.types:
            filling = view.pending.get(("fill", pot))
            if filling is not None:
                if filling.progressing:
                    return None
                if filling.station is not None and not view.is_free(filling.station):
                    return self.clear_station(view, filling.station)
                return self.fetch(view, pot)
            if station is not None and view.true("issink", station):
                return self.goto(view, station) or self.act(view, "fill-pot", c1=pot, s1=station)
            if self.free_station(view, "issink") is None:
                return self.clear_one(view, "issink")
            return self.fetch(view, pot)
        if soup.boil and not view.true("isboiling", water) and view.meal_in.get(water) == pot:
            pending = view.pending.get(("isboiling", water))
            if pending is not None:
                if pending.station == station:
                    return None
                if pending.station is not None and not view.is_free(pending.station):
                    return self.clear_station(view, pending.station)
                return self.fetch(view, pot)
            if station is not None and view.true("isstove", station):
                return self.goto(view, station) or self.act(view, "boil-water", c1=pot, m1=water, s1=station)
            if self.free_station(view, "isstove") is None:
                return self.clear_one(view, "isstove")
            return self.fetch(view, pot)
        return None

    def lay_bases(self, view: View) -> Grounding | None:
        """Clear each dish's table of wrong items and lay its prepared base; bring each soup's bowl to its table."""
        options = []
        for dish in self.recipe.dishes:
            good, bad = self.dish_state(dish, view)
            table = self.assign[dish.table]
            if bad:
                options.append((table, self.fetch(view, bad[-1])))
                continue
            if good:
                continue
            if table in view.station_container:
                options.append((table, self.fetch(view, view.station_container[table])))
                continue
            base = self.assign[dish.base]
            if self.ready(dish.base, base, view) and base in view.where:
                options.append((base, self.fetch(view, base)))
        for soup in self.recipe.soups:
            if soup.table is None:
                continue
            bowl = self.assign[soup.bowl]
            table = self.assign[soup.table]
            if view.container_at.get(bowl) == table:
                continue
            if not view.is_free(table):
                options.append((table, self.clear_station(view, table)))
                continue
            if bowl in view.container_at:
                options.append((bowl, self.fetch(view, bowl)))
        return self._closest(options, view)

    def cut_jobs(self, view: View) -> Grounding | None:
        """A step towards cutting an item whose next preparation is cutting (the job picked by :meth:`_closest`)."""
        options = []
        for var in self.recipe.item_vars:
            obj = self.assign[var]
            if self.needs(var, obj, view)[:1] == ["iscut"]:
                options.append((obj, self.prep_step(var, obj, view)))
        return self._closest(options, view)

    def assemble(self, view: View) -> Grounding | None:
        """Fetch the next ready item of a dish, or a ready ingredient for a soup whose pot stands on a station."""
        options = []
        for dish in self.recipe.dishes:
            for var in self.dish_next(dish, view):
                obj = self.assign[var]
                if self.ready(var, obj, view) and obj in view.where and not busy(obj, view):
                    options.append((obj, self.fetch(view, obj)))
        for soup in self.recipe.soups:
            water = self.assign[soup.water]
            pot = self.soup_pot(soup, view)
            if pot is None or view.meal_in.get(water) != pot or pot not in view.container_at:
                continue
            for var in soup.ingredients:
                obj = self.assign[var]
                if obj in view.added or not self.ready(var, obj, view) or obj not in view.where:
                    continue
                if busy(obj, view):
                    continue
                options.append((obj, self.fetch(view, obj)))
        return self._closest(options, view)

    def pour(self, view: View) -> Grounding | None:
        """Fetch a finished soup's pot (boiled if required, every ingredient added) to pour it into its bowl."""
        for soup in self.recipe.soups:
            water = self.assign[soup.water]
            pot = self.soup_pot(soup, view)
            if pot is None or pot not in view.container_at:
                continue
            if soup.boil and not view.true("isboiling", water):
                continue
            if not all(view.added.get(self.assign[i]) == water for i in soup.ingredients):
                continue
            bowl = self.assign[soup.bowl]
            table = self.assign[soup.table] if soup.table is not None else None
            if view.container_at.get(bowl) is None or (table is not None and view.container_at[bowl] != table):
                continue
            return self.fetch(view, pot)
        return None

    def wait(self, view: View) -> Grounding | None:
        """While a timer runs: go to where the soonest result appears, else do nothing for a step; None when no timer runs."""
        running = [p for p in view.pending.values() if p.progressing]
        if not running:
            return None
        soonest = min(running, key=lambda p: p.remaining)
        if soonest.station is not None and soonest.station != view.loc:
            return self.goto(view, soonest.station)
        return self.act(view, "wait")


def expert_plan(state: State, goal: Goal, limit: int = 400) -> list[str] | None:
    """Actions that reach ``goal`` from ``state`` (None when the planner finds no way)."""
    try:
        planner = Planner(state, goal)
    except UnsupportedGoal:
        return None
    return planner.plan(state, limit)
