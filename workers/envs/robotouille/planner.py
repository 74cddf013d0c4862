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

from .effects import base_name
from .goal import Goal
from .kitchen_view import View, busy
from .recipe import PREP, Recipe, Soup, StackDish, UnsupportedGoal, analyze
from .roles import INF, RoleChooser
from .state import Grounding, State


class Planner:
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

    # ------------------------------------------------------------ roles
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

    # ---------------------------------------------------------------- policy
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

    # roles seen from the objects
    def var_of(self, obj: str) -> int | None:
        """The goal variable ``obj`` plays; None for an object in no role."""
        return self.role.get(obj)

    def reserved(self, view: View) -> set[str]:
        """Stations not to put things on: goal tables, and where a timer runs or will resume.

        A paused timer keeps its station only while its result is still wanted (a chicken that
        is already cooked does not need its old stove back).
        """
        out = {self.assign[v] for v in self.recipe.table_vars}
        wanted = set(self.assign.values())
        for (pred, subject), p in view.pending.items():
            if p.station is None:
                continue
            if pred == "fill":
                still_wanted = True  # a pot filling with water: the soup needs it
            else:
                still_wanted = subject in wanted and not view.true(pred, subject)
            if p.progressing or still_wanted:
                out.add(p.station)
        return out

    def free_station(self, view: View, pred: str, prefer_loc: bool = True) -> str | None:
        """A free, unreserved station of kind ``pred`` (the robot's own first when ``prefer_loc``); None when there is none."""
        reserved = self.reserved(view)
        free = [s for s in self.kind_stations[pred] if view.is_free(s) and s not in reserved]
        if not free:
            return None
        if prefer_loc and view.loc in free:
            return view.loc
        return free[0]

    def demand(self, view: View) -> dict[str, int]:
        """Stations of each kind (board, stove, fryer, sink) that the preparations still to come will need:
        parking must leave that many free."""
        need = {"isboard": 0, "isstove": 0, "isfryer": 0, "issink": 0}
        for v in self.recipe.item_vars:
            obj = self.assign.get(v)
            if obj is None:
                continue
            for prep in self.needs(v, obj, view):
                need[PREP[prep][0]] += 1
        for soup in self.recipe.soups:
            if soup.water and self.assign[soup.water] not in view.st.types:
                need["issink"] += 1
            if soup.boil and not view.true("isboiling", self.assign[soup.water]):
                need["isstove"] += 1
        return need

    def need_rank(self, obj: str | None) -> float:
        """How soon an object is wanted (lower = sooner); objects in no role: never (inf)."""
        var = self.role.get(obj) if obj is not None else None
        if var is None:
            return INF
        dish = self.dish_of.get(var)
        if dish is not None:
            return 100 * self.recipe.dishes.index(dish) + self.dish_order(dish).index(var)
        return 50

    def eff_rank(self, obj: str, view: View) -> float:
        """need_rank, but an object still to be prepared is wanted first of all (-1)."""
        if obj == self.focus:
            return -2  # the object the robot is digging out right now
        var = self.role.get(obj)
        if var is not None and self.prep_target(var, obj, view) is not None:
            return -1
        return self.need_rank(obj)

    def dish_order(self, dish: StackDish) -> list[int]:
        """The dish's variables in stacking order: the base, the ``atop`` chain upward from it, the loose
        members, and the top item last."""
        chain = [dish.base]
        below_of = {b: a for a, b in dish.below.items()}
        while chain[-1] in below_of:
            chain.append(below_of[chain[-1]])
        loose = [v for v in dish.members if v not in chain and v != dish.top]
        return chain + loose + ([dish.top] if dish.top is not None and dish.top not in chain else [])

    def park_station(self, view: View) -> str | None:
        """Where to put down what the robot holds for now, without blocking what is needed.

        Empty spare stations first (tables, then kinds with more free stations than pending
        preparations need); else on top of a pile of unneeded things; else on an item that is
        needed *after* the held one (last in, first out); as a last resort anywhere.
        """
        reserved = self.reserved(view)
        need = self.demand(view)
        rank = self.need_rank(view.held_item) if view.held_item else INF
        spare: dict[str, int] = {}
        for pred, stations in self.kind_stations.items():
            spare[pred] = sum(1 for s in stations if view.is_free(s) and s not in reserved)
        timers = {p.station for p in view.pending.values() if p.station and p.progressing}
        best: tuple[float, int, int] | None = None
        for k, s in enumerate(view.st.objects["station"]):
            if s in timers:
                continue
            if s in reserved:
                # a goal table, only when nothing else is possible (and only while empty)
                if view.is_free(s):
                    key = (30.0, 0 if s == view.loc else 1, k)
                    if best is None or key < best:
                        best = key
                continue
            pred = next((p for p, sts in self.kind_stations.items() if s in sts), "")
            tight = pred != "istable" and spare.get(pred, 0) <= need.get(pred, 0)
            if view.is_free(s):
                score = 0.0 if pred == "istable" else (10.0 if tight else 1.0)
                if s == self.picked_from:
                    score += 20.0  # straight back where it came from undoes the last step
            elif view.held_item is not None and s in view.stacks:
                stack = view.stacks[s]
                bottom_var = self.role.get(stack[0])
                prep = self.prep_target(bottom_var, stack[0], view) if bottom_var is not None else None
                if prep is not None and view.true(prep[1], s):
                    continue  # would block its preparation right here
                soonest = min(self.eff_rank(x, view) for x in stack)
                if soonest == INF:
                    score = 2.0
                elif soonest > rank:
                    score = 3.0 + 1.0 / (3 + soonest)
                else:
                    score = 8.0 + 1.0 / (3 + soonest)
                if s == self.picked_from:
                    score += 20.0  # straight back where it came from undoes the last step
                if tight:
                    score += 6.0  # a preparation station that will have to be cleared again
            else:
                continue
            key = (score, 0 if s == view.loc else 1, k)
            if best is None or key < best:
                best = key
        return None if best is None else view.st.objects["station"][best[2]]

    def park(self, view: View) -> Grounding | None:
        """Put down what the robot holds at :meth:`park_station` (moving there first); None when there is nowhere."""
        station = self.park_station(view)
        return None if station is None else self.put(view, station)

    # dish bookkeeping
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

    # ------------------------------------------------------------- the policy
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

    def prep_target(self, var: int, obj: str, view: View) -> tuple[str, str] | None:
        """(next preparation, station predicate) for a role object; None when ready."""
        for prep in self.needs(var, obj, view):
            return prep, PREP[prep][0]
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

    def clear_one(self, view: View, pred: str) -> Grounding | None:
        """Free a station of kind ``pred`` by taking the top of a stack nobody is waiting on."""
        reserved = self.reserved(view)
        for s in self.kind_stations[pred]:
            if s in reserved:
                continue
            top = view.top(s)
            if top is not None:
                bottom = view.stacks[s][0]
                bvar = self.var_of(bottom)
                target = self.prep_target(bvar, bottom, view) if bvar is not None else None
                if len(view.stacks[s]) == 1 and target is not None and target[1] == pred:
                    continue  # it is being prepared here
                if busy(top, view):
                    continue
                return self.fetch(view, top)
            if s in view.station_container:
                c = view.station_container[s]
                if busy(c, view) or busy(view.container_meal.get(c, ""), view):
                    continue
                return self.fetch(view, c)
        return None

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

    def clear_station(self, view: View, station: str) -> Grounding | None:
        """Step towards emptying ``station``: fetch its top item, else its container; None when it is already free."""
        top = view.top(station)
        if top is not None:
            return self.fetch(view, top)
        if station in view.station_container:
            return self.fetch(view, view.station_container[station])
        return None

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
