"""Where the expert planner puts things down and which stations it keeps free (parking and clearing).

Split from :mod:`.planner` so the policy reads as its jobs; these rules decide only *where*:
stations reserved for goals and running timers, how many of each kind the preparations still need,
and which pile a held item may go on without burying something wanted sooner.
"""

from __future__ import annotations

from .kitchen_view import View, busy
from .planner_steps import PlannerBase
from .recipe import PREP
from .roles import INF
from .state import Grounding


class ParkingPlanner(PlannerBase):
    """:class:`PlannerBase` plus the parking and clearing rules the policy calls when something is in the way."""

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
