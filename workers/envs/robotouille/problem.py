"""Build the initial engine state and the goal from a Robotouille problem JSON.

A problem lists stations, items, players, containers and meals on a grid. Objects of each kind are
stably sorted by (x, y) and named ``<name><n>`` (n counts per name in that order). A player stands
at the station at position + direction; an item or container in a player's cell is held; items in
a station's cell stack by ``stack-level``; a meal shares its container's cell.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from typing import Any

from .data import DataFileError
from .domain import Domain
from .goal import Goal, parse_goal
from .state import State

#: problem-file key per object type
KIND_KEYS = {"station": "stations", "item": "items", "player": "players", "container": "containers", "meal": "meals"}


@dataclass
class Problem:
    """A built problem: the initial engine state, the goal, and the goal sentence shown to the agent."""

    state: State
    goal: Goal
    goal_description: str


def build_problem(domain: Domain, raw: Any, source: str = "problem") -> Problem:
    """The initial state and goal of a problem (``generated_environment_json`` of an instance)."""
    try:
        return _build(domain, raw, source)
    except DataFileError:
        raise
    except (KeyError, TypeError, ValueError, AttributeError, IndexError) as exc:
        raise DataFileError(f"{source}: not a Robotouille problem ({type(exc).__name__}: {exc})") from None


def _build(domain: Domain, raw: dict, source: str) -> Problem:
    state = State(domain, raw.get("config") or {})
    grid = _Grid(state, source)
    grid.name_objects(domain, raw)
    grid.add_kinds()
    grid.place_players()
    grid.place_items()
    grid.place_containers()
    grid.place_meals()
    grid.add_stacks()
    grid.add_free()
    goal = parse_goal(raw["goal"], state, source)
    return Problem(state, goal, str(raw.get("goal_description", "")))


class _Grid:
    """A problem's grid read into the state's objects and facts, one kind of object at a time."""

    def __init__(self, state: State, source: str) -> None:
        self.state = state
        self.source = source
        self.placed: dict[str, list[tuple[str, dict]]] = {}
        self.station_at: dict[tuple[int, int], str] = {}
        self.player_at: dict[tuple[int, int], str] = {}
        self.occupied: set[str] = set()
        self.busy_players: set[str] = set()
        self.stacks: dict[str, list[tuple[int, str]]] = defaultdict(list)
        self.filled: set[str] = set()
        self.container_at_cell: dict[tuple[int, int], str] = {}
        self.full_containers: set[str] = set()

    def add(self, pred: str, *args: str) -> None:
        """One fact; a predicate the domain does not know is a data error."""
        facts = self.state.facts
        if pred not in facts:
            raise DataFileError(f"{self.source}: predicate {pred!r} is not in the domain")
        facts[pred].add(args)

    def name_objects(self, domain: Domain, raw: dict) -> None:
        """Every object, kind by kind, sorted by (x, y) and named ``<name><n>``."""
        for obj_type in domain.object_types:
            entries = list(raw.get(KIND_KEYS.get(obj_type, obj_type + "s"), None) or [])
            entries.sort(key=lambda o: (o["x"], o["y"]))  # stable: file order breaks ties
            counters: dict[str, int] = defaultdict(int)
            named = []
            for entry in entries:
                counters[entry["name"]] += 1
                name = f"{entry['name']}{counters[entry['name']]}"
                self.state.add_object(name, obj_type)
                named.append((name, entry))
            self.placed[obj_type] = named
        self.station_at = {(e["x"], e["y"]): n for n, e in self.placed.get("station", [])}
        self.player_at = {(e["x"], e["y"]): n for n, e in self.placed.get("player", [])}

    def add_kinds(self) -> None:
        """``is<name>`` for every object, and the predicates its entry lists."""
        for _obj_type, named in self.placed.items():
            for name, entry in named:
                self.add("is" + entry["name"], name)
                for pred in entry.get("predicates", ()) or ():
                    self.add(pred, name)

    def place_players(self) -> None:
        """Each player at the station it faces."""
        for name, entry in self.placed.get("player", []):
            dx, dy = entry["direction"]
            cell = (entry["x"] + dx, entry["y"] + dy)
            if cell not in self.station_at:
                raise DataFileError(f"{self.source}: player {name} faces no station at {cell}")
            self.add("loc", name, self.station_at[cell])
            self.occupied.add(self.station_at[cell])

    def place_items(self) -> None:
        """Items on a station join its stack (by ``stack-level``); items in a player's cell are held."""
        for name, entry in self.placed.get("item", []):
            cell = (entry["x"], entry["y"])
            if cell in self.station_at:
                self.stacks[self.station_at[cell]].append((int(entry.get("stack-level", 0)), name))
            elif cell in self.player_at:
                self.add("has_item", self.player_at[cell], name)
                self.busy_players.add(self.player_at[cell])
            else:
                raise DataFileError(f"{self.source}: item {name} is neither on a station nor held")

    def place_containers(self) -> None:
        """Containers on a station fill it; containers in a player's cell are held."""
        for name, entry in self.placed.get("container", []):
            cell = (entry["x"], entry["y"])
            self.container_at_cell[cell] = name
            if cell in self.station_at:
                self.add("container_at", name, self.station_at[cell])
                self.stacks.setdefault(self.station_at[cell], [])
                self.filled.add(self.station_at[cell])
            elif cell in self.player_at:
                self.add("has_container", self.player_at[cell], name)
                self.busy_players.add(self.player_at[cell])
            else:
                raise DataFileError(f"{self.source}: container {name} is neither on a station nor held")

    def place_meals(self) -> None:
        """Each meal in the container that shares its cell."""
        for name, entry in self.placed.get("meal", []):
            cell = (entry["x"], entry["y"])
            if cell not in self.container_at_cell:
                raise DataFileError(f"{self.source}: meal {name} is not in a container")
            self.add("in", name, self.container_at_cell[cell])
            self.full_containers.add(self.container_at_cell[cell])

    def add_stacks(self) -> None:
        """Each station's stack, bottom up: ``item_at``, ``item_on`` / ``atop``, ``clear`` on its top."""
        for station, items in self.stacks.items():
            items.sort(key=lambda r: r[0])
            names = [n for _, n in items]
            for k, item in enumerate(names):
                self.add("item_at", item, station)
                if k == 0:
                    self.add("item_on", item, station)
                else:
                    self.add("atop", item, names[k - 1])
            if names:
                self.add("clear", names[-1])
                self.filled.add(station)

    def add_free(self) -> None:
        """What is free: ``vacant`` and ``station_empty`` stations, idle players (``nothing``), empty containers."""
        state = self.state
        for station in state.objects["station"]:
            if station not in self.occupied:
                self.add("vacant", station)
            if station not in self.filled:
                self.add("station_empty", station)
        for player in state.objects["player"]:
            if player not in self.busy_players:
                self.add("nothing", player)
        for container in state.objects["container"]:
            if container not in self.full_containers:
                self.add("container_empty", container)
