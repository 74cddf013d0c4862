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
    placed: dict[str, list[tuple[str, dict]]] = {}
    for obj_type in domain.object_types:
        entries = list(raw.get(KIND_KEYS.get(obj_type, obj_type + "s"), None) or [])
        entries.sort(key=lambda o: (o["x"], o["y"]))  # stable: file order breaks ties
        counters: dict[str, int] = defaultdict(int)
        named = []
        for entry in entries:
            counters[entry["name"]] += 1
            name = f"{entry['name']}{counters[entry['name']]}"
            state.add_object(name, obj_type)
            named.append((name, entry))
        placed[obj_type] = named

    facts = state.facts

    def add(pred: str, *args: str) -> None:
        if pred not in facts:
            raise DataFileError(f"{source}: predicate {pred!r} is not in the domain")
        facts[pred].add(args)

    for _obj_type, named in placed.items():
        for name, entry in named:
            add("is" + entry["name"], name)
            for pred in entry.get("predicates", ()) or ():
                add(pred, name)

    station_at = {(e["x"], e["y"]): n for n, e in placed.get("station", [])}
    player_at = {(e["x"], e["y"]): n for n, e in placed.get("player", [])}
    occupied: set[str] = set()
    busy_players: set[str] = set()
    for name, entry in placed.get("player", []):
        dx, dy = entry["direction"]
        cell = (entry["x"] + dx, entry["y"] + dy)
        if cell not in station_at:
            raise DataFileError(f"{source}: player {name} faces no station at {cell}")
        add("loc", name, station_at[cell])
        occupied.add(station_at[cell])

    stacks: dict[str, list[tuple[int, str]]] = defaultdict(list)
    for name, entry in placed.get("item", []):
        cell = (entry["x"], entry["y"])
        if cell in station_at:
            stacks[station_at[cell]].append((int(entry.get("stack-level", 0)), name))
        elif cell in player_at:
            add("has_item", player_at[cell], name)
            busy_players.add(player_at[cell])
        else:
            raise DataFileError(f"{source}: item {name} is neither on a station nor held")
    filled: set[str] = set()
    container_at_cell: dict[tuple[int, int], str] = {}
    for name, entry in placed.get("container", []):
        cell = (entry["x"], entry["y"])
        container_at_cell[cell] = name
        if cell in station_at:
            add("container_at", name, station_at[cell])
            stacks.setdefault(station_at[cell], [])
            filled.add(station_at[cell])
        elif cell in player_at:
            add("has_container", player_at[cell], name)
            busy_players.add(player_at[cell])
        else:
            raise DataFileError(f"{source}: container {name} is neither on a station nor held")
    full_containers: set[str] = set()
    for name, entry in placed.get("meal", []):
        cell = (entry["x"], entry["y"])
        if cell not in container_at_cell:
            raise DataFileError(f"{source}: meal {name} is not in a container")
        add("in", name, container_at_cell[cell])
        full_containers.add(container_at_cell[cell])

    for station, items in stacks.items():
        items.sort(key=lambda r: r[0])
        names = [n for _, n in items]
        for k, item in enumerate(names):
            add("item_at", item, station)
            if k == 0:
                add("item_on", item, station)
            else:
                add("atop", item, names[k - 1])
        if names:
            add("clear", names[-1])
            filled.add(station)
    for station in state.objects["station"]:
        if station not in occupied:
            add("vacant", station)
        if station not in filled:
            add("station_empty", station)
    for player in state.objects["player"]:
        if player not in busy_players:
            add("nothing", player)
    for container in state.objects["container"]:
        if container not in full_containers:
            add("container_empty", container)

    goal = parse_goal(raw["goal"], state, source)
    return Problem(state, goal, str(raw.get("goal_description", "")))
