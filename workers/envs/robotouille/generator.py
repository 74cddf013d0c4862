"""Robotouille's seeded kitchen randomiser, re-implemented so the benchmark instances can be rebuilt.

Why: the 200 benchmark instances (and the two demonstration kitchens) are not stored upstream;
the real engine makes each one at load time from a problem file
(``environments/env_generator/examples/<split>/<task>.json``) and a seed. To reproduce them on a
fresh machine without copying the recorded files, this module replays the same computation:
every draw from Python's Mersenne-Twister generator happens in the same order, with the same
bounds, as in the real engine (commit c8236a2e of portal-cornell/robotouille, branch
``release``, ``noisy_randomization=False``, the only mode the benchmark uses). A different draw
order, a different kind list, or a different key order in the output would give other kitchens,
so the details below are deliberate, not style.

What one attempt does (:func:`randomize`), in draw order:

1. ``Random(seed)``; a number of *extra* stations ``randrange(w*h)``, each at
   ``(randrange(w), randrange(h))``; then one kind each from :data:`STATION_KINDS`.
2. A number of extra items ``randrange(stations+1)``; each takes its x from one random extra
   station and its y from another (two independent draws); then one kind each from
   :data:`ITEM_KINDS` (cookable/cuttable kinds get that predicate).
3. The problem's own objects, one by one, each moved to a random cell and marked ``force_add``:
   stations, items, containers, then players (which also draw a facing direction).
4. Placement. Stations (extras first, then the problem's): a free cell is taken when every
   station stays reachable; a ``force_add`` station displaces an extra one on a clash, or a random
   extra one when it would block. The player goes next to the first station (in list order) that
   has a free neighbour from which every station is reachable; its random cell is not used. Items
   and containers then need a station or the player under them; extras that do not fit are
   dropped, ``force_add`` ones displace extras.
5. Every item is put back to ``stack-level`` 0 (stacks are not randomised).

Before all this, the real engine's loader sorts each object list of the problem file by (x, y)
(:func:`as_loaded`); the draws of step 3 follow that order. Only ``noisy_randomization=False``
is implemented (the "frozen" groups of the noisy mode are not used by the benchmark).

An attempt can fail (no extra station left to displace, a forced item or container with nowhere
to go, or a forced container meeting an extra item on its cell: the real engine crashes there on
a typo). The real engine then silently tries ``seed + 1``, ``seed + 2``, ...; :func:`generate`
does the same and reports the seed that worked.

Verified against every recorded instance by ``bench/robotouille_generator.py``.
"""

from __future__ import annotations

import copy
import json
import random
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from . import catalog
from .data import read_json
from .domain import load_domain
from .problem import build_problem

#: kinds an extra station can be, in the order the real engine draws from (its ``Station`` enum)
STATION_KINDS = ("board", "stove", "table", "fryer", "sink")
#: kinds an extra item can be, in the order the real engine draws from (its ``Item`` enum)
ITEM_KINDS = ("bottombun", "lettuce", "patty", "topbun", "bread", "cheese", "tomato", "onion", "chicken", "potato")
#: the predicate an extra item of a kind starts with (kinds not listed get none)
_KIND_PREDICATE = {
    "patty": "iscookable",
    "chicken": "iscookable",
    "lettuce": "iscuttable",
    "onion": "iscuttable",
    "tomato": "iscuttable",
}
#: the name an extra object has until its kind is drawn (it fixes the key order: name first)
STATION_WILDCARD = "station"
ITEM_WILDCARD = "item"
#: facing directions a player can draw, in draw order
DIRECTIONS = ([0, 1], [1, 0], [0, -1], [-1, 0])
#: object lists the real engine's loader sorts by (x, y) before randomising, in its order
LOADER_SORTED = ("stations", "items", "players", "containers", "meals")
FORCE = "force_add"
#: the real engine retries without bound; no recorded instance needed more than 4 extra seeds
MAX_ATTEMPTS = 100


class GenerationFailed(Exception):
    """One attempt could not place a required object (the real engine moves on to seed + 1)."""


@dataclass(frozen=True)
class Generated:
    """The randomised problem and the layout seed that produced it (the one asked for or a later one;
    ``used_seed`` as the recorded instance files name it)."""

    problem: dict[str, Any]
    used_seed: int


def generate(problem: dict[str, Any], layout_seed: int, max_attempts: int = MAX_ATTEMPTS) -> Generated:
    """Randomise a problem file's content as the real engine does for the kitchen's ``layout_seed``
    (after its loader's sort, :func:`as_loaded`), retrying layout_seed+1, ... on failure."""
    problem = as_loaded(problem)
    for used in range(layout_seed, layout_seed + max_attempts):
        try:
            return Generated(randomize(problem, used), used)
        except GenerationFailed:
            continue
    raise GenerationFailed(f"no kitchen could be generated for seeds {layout_seed}..{layout_seed + max_attempts - 1}")


def as_loaded(problem: dict[str, Any]) -> dict[str, Any]:
    """The problem as the real engine's loader hands it to the randomiser: each object list
    stably sorted by (x, y). The loader also renames wildcard objects (``"station"``, ...) with
    draws from the *unseeded* global generator, which cannot be replayed: refused here."""
    loaded = copy.deepcopy(problem)
    for key in LOADER_SORTED:
        if key not in loaded:
            continue
        for obj in loaded[key]:
            if obj.get("name") == key[:-1]:
                raise ValueError(f"problem {key} has a wildcard {obj['name']!r}: its kind is drawn unseeded upstream")
        loaded[key].sort(key=lambda o: (o["x"], o["y"]))
    return loaded


def randomize(problem: dict[str, Any], layout_seed: int) -> dict[str, Any]:
    """One attempt at ``layout_seed`` on an already loaded problem (:func:`as_loaded`): the
    randomised problem, or GenerationFailed."""
    rng = random.Random(layout_seed)
    width, height = int(problem["width"]), int(problem["height"])
    grid = _Grid(width, height)

    extra_stations = _extra_stations(rng, width, height)
    extra_items = _extra_items(rng, extra_stations)
    own = {key: copy.deepcopy(problem.get(key, [])) for key in ("stations", "items", "containers", "players")}
    for obj in own["stations"] + own["items"] + own["containers"]:
        _move(rng, obj, width, height)
        obj[FORCE] = True  # (upstream would draw a kind here for a wildcard: as_loaded refuses them)
    for player in own["players"]:
        _move(rng, player, width, height)
        player["direction"] = list(rng.choice(DIRECTIONS))
        player[FORCE] = True

    out = copy.deepcopy(problem)
    for key in ("stations", "items", "containers", "players"):
        out[key] = []  # keeps the key's place; a key the problem lacks goes last, as upstream
    stations = _place_stations(rng, grid, extra_stations + own["stations"], own["players"])
    players = _place_player(grid, stations, own["players"])
    items = _place_items(stations + players, extra_items + own["items"])
    containers = _place_containers(stations + players, items, own["containers"])
    for item in items:
        item["stack-level"] = 0
    out["stations"], out["players"] = stations, players
    out["items"], out["containers"] = copy.deepcopy(items), containers
    return out


# ---------------------------------------------------------------------------------------------
# drawing the objects


def _extra_stations(rng: random.Random, width: int, height: int) -> list[dict[str, Any]]:
    count = rng.randrange(0, width * height)
    stations = [{"name": STATION_WILDCARD, "x": rng.randrange(0, width), "y": rng.randrange(0, height)} for _ in range(count)]
    for station in stations:  # all cells are drawn before any kind
        station["name"] = rng.choice(STATION_KINDS)
    return stations


def _extra_items(rng: random.Random, stations: list[dict[str, Any]]) -> list[dict[str, Any]]:
    count = rng.randrange(0, len(stations) + 1)
    items = []
    for _ in range(count):
        x = rng.choice(stations)["x"]
        y = rng.choice(stations)["y"]  # a second, independent station: the cell may hold none
        items.append({"name": ITEM_WILDCARD, "x": x, "y": y, "stack-level": 0})
    for item in items:
        _name_item(rng, item)
    return items


def _name_item(rng: random.Random, item: dict[str, Any]) -> None:
    kind = rng.choice(ITEM_KINDS)
    item["name"] = kind
    if kind in _KIND_PREDICATE:
        item["predicates"] = [_KIND_PREDICATE[kind]]


def _move(rng: random.Random, obj: dict[str, Any], width: int, height: int) -> None:
    obj["x"] = rng.randrange(0, width)  # x before y: two draws in this order
    obj["y"] = rng.randrange(0, height)


# ---------------------------------------------------------------------------------------------
# reachability


class _Grid:
    """Which stations a walker can reach (stations block; moves are the four neighbours)."""

    def __init__(self, width: int, height: int) -> None:
        self.width, self.height = width, height

    def all_reachable(self, stations: list[dict[str, Any]], player: dict[str, Any] | None) -> bool:
        """With a player: every station borders the open region around the player's cell (a
        player standing on a station reaches that one only). Without: some open region borders
        every station (none at all when the grid has no open cell)."""
        occupied = {(s["x"], s["y"]) for s in stations}
        if player is not None:
            start = (player["x"], player["y"])
            if start in occupied:
                return len(stations) == 1
            return self._bordering(start, occupied) == len(stations)
        seen: set[tuple[int, int]] = set()
        for cell in self._cells():
            if cell in occupied or cell in seen:
                continue
            if self._bordering(cell, occupied, seen) == len(stations):
                return True
        return False

    def _cells(self) -> Iterable[tuple[int, int]]:
        return ((x, y) for y in range(self.height) for x in range(self.width))

    def _bordering(self, start: tuple[int, int], occupied: set[tuple[int, int]], seen: set[tuple[int, int]] | None = None) -> int:
        """Number of distinct stations next to the open region containing ``start``."""
        seen = set() if seen is None else seen
        touched: set[tuple[int, int]] = set()
        todo = [start]
        seen.add(start)
        while todo:
            x, y = todo.pop()
            for cell in ((x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)):
                if not (0 <= cell[0] < self.width and 0 <= cell[1] < self.height):
                    continue
                if cell in occupied:
                    touched.add(cell)
                elif cell not in seen:
                    seen.add(cell)
                    todo.append(cell)
        return len(touched)


# ---------------------------------------------------------------------------------------------
# placing the objects


def _at(objs: Iterable[dict[str, Any]], x: int, y: int) -> list[dict[str, Any]]:
    return [o for o in objs if o["x"] == x and o["y"] == y]


def _index_of(objs: list[dict[str, Any]], target: dict[str, Any]) -> int:
    """First position holding an object equal to ``target`` (upstream compares by value)."""
    return objs.index(target)


def _place_stations(
    rng: random.Random, grid: _Grid, candidates: list[dict[str, Any]], players: list[dict[str, Any]]
) -> list[dict[str, Any]]:
    placed: list[dict[str, Any]] = []
    # an extra station is checked against the player's drawn cell (upstream passes the players
    # still to be placed); a forced one against no player at all
    walker = players[0] if players else None
    for station in candidates:
        clash = _at(placed, station["x"], station["y"])
        if not station.get(FORCE):
            if not clash and grid.all_reachable(placed + [station], walker):
                placed.append(station)
            continue
        if clash and not clash[0].get(FORCE):
            spot = _index_of(placed, clash[0])
            station["x"], station["y"] = clash[0]["x"], clash[0]["y"]
            placed[spot] = station
            continue
        if not clash and grid.all_reachable(placed + [station], None):
            placed.append(station)
            continue
        extras = [s for s in placed if s.get(FORCE) is None]
        if not extras:
            raise GenerationFailed("no extra station left to make room for a required one")
        victim = rng.choice(extras)
        spot = _index_of(placed, victim)
        station["x"], station["y"] = victim["x"], victim["y"]
        placed[spot] = station
    return placed


def _place_player(grid: _Grid, stations: list[dict[str, Any]], players: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Only the first player is placed (the benchmark has one); its drawn cell is ignored."""
    if not players:
        raise GenerationFailed("the problem has no player")
    player = dict(players[0])
    taken = {(s["x"], s["y"]) for s in stations}
    for station in stations:
        x, y = station["x"], station["y"]
        for nx, ny in ((x, y + 1), (x, y - 1), (x + 1, y), (x - 1, y)):
            if not (0 <= nx < grid.width and 0 <= ny < grid.height) or (nx, ny) in taken:
                continue
            player["x"], player["y"] = nx, ny
            player["direction"] = [x - nx, y - ny]
            if grid.all_reachable(stations, player):
                return [player]
    return []


def _place_items(holders: list[dict[str, Any]], candidates: list[dict[str, Any]]) -> list[dict[str, Any]]:
    placed: list[dict[str, Any]] = []
    for item in candidates:
        under = _at(holders, item["x"], item["y"])
        clash = _at(placed, item["x"], item["y"])
        if under and not clash:
            placed.append(item)
        elif not item.get(FORCE):
            continue
        elif under and clash and not clash[0].get(FORCE):
            spot = _index_of(placed, clash[0])
            item["x"], item["y"] = clash[0]["x"], clash[0]["y"]
            placed[spot] = item
        else:
            _force_item(holders, placed, item)
    return placed


def _force_item(holders: list[dict[str, Any]], placed: list[dict[str, Any]], item: dict[str, Any]) -> None:
    """A required item that found no room: the first holder that is free or holds an extra item."""
    for holder in holders:
        there = _at(placed, holder["x"], holder["y"])
        if not there:
            item["x"], item["y"] = holder["x"], holder["y"]
            placed.append(item)
            return
        if there[0].get(FORCE) is None:
            spot = _index_of(placed, there[0])
            item["x"], item["y"] = there[0]["x"], there[0]["y"]
            placed[spot] = item
            return
    raise GenerationFailed("a required item has nowhere to go")


def _place_containers(
    holders: list[dict[str, Any]], items: list[dict[str, Any]], candidates: list[dict[str, Any]]
) -> list[dict[str, Any]]:
    """Containers go on free holders; ``items`` loses an extra item a forced container displaces."""
    placed: list[dict[str, Any]] = []
    for container in candidates:
        under = _at(holders, container["x"], container["y"])
        item_clash = _at(items, container["x"], container["y"])
        box_clash = _at(placed, container["x"], container["y"])
        if under and not (item_clash or box_clash):
            placed.append(container)
        elif not container.get(FORCE):
            continue
        elif under and item_clash and not item_clash[0].get(FORCE):
            # the real engine crashes here (it indexes the removed item as if it were a list),
            # so the attempt fails and the next seed is tried
            raise GenerationFailed("a required container landed on an extra item")
        elif under and box_clash and not box_clash[0].get(FORCE):
            spot = _index_of(placed, box_clash[0])
            container["x"], container["y"] = box_clash[0]["x"], box_clash[0]["y"]
            placed[spot] = container
        else:
            _force_container(holders, items, placed, container)
    return placed


def _force_container(
    holders: list[dict[str, Any]], items: list[dict[str, Any]], placed: list[dict[str, Any]], container: dict[str, Any]
) -> None:
    for holder in holders:
        boxes = _at(placed, holder["x"], holder["y"])
        things = _at(items, holder["x"], holder["y"])
        if not boxes and not things:
            container["x"], container["y"] = holder["x"], holder["y"]
            placed.append(container)
            return
        if boxes and boxes[0].get(FORCE) is None:
            spot = _index_of(placed, boxes[0])
            container["x"], container["y"] = boxes[0]["x"], boxes[0]["y"]
            placed[spot] = container
            return
        if things and things[0].get(FORCE) is None:
            items.remove(things[0])
            container["x"], container["y"] = things[0]["x"], things[0]["y"]
            placed.append(container)
            return
    raise GenerationFailed("a required container has nowhere to go")


# ---------------------------------------------------------------------------------------------
# instance files: what `recap data fetch robotouille` writes into instances/ and instances_train/

#: where the problem files are in a data folder (upstream's layout)
EXAMPLES_DIR = "environments/env_generator/examples"
#: the two demonstration kitchens and the layout seed the paper's one-shot examples use
TRAIN_KITCHENS = (("synchronous_train", "0_cheese_onion_sandwich"), ("asynchronous_train", "0_chicken_onion_sandwich"))
TRAIN_SEED = 26
#: step cap multiplier of Robotouille's own configs (the recorded files' ``max_steps``)
UPSTREAM_STEP_MULTIPLIER = 1.5
GENERATED_BY = "recap-eval workers/envs/robotouille/generator.py (re-implementation of the real engine's seeded generator)"


def instance_record(root: Path, environment_name: str, layout_seed: int, optimal_steps: int | None) -> dict[str, Any]:
    """One instance file's content, in the recorded files' field order (its ``seed`` is the layout
    seed, as upstream's files name it). The real engine's own
    measurements (build times, its internal predicate count) are left out: they cannot be
    reproduced; everything else is computed (first observation and goal-set count by our engine)."""
    problem_file = root / EXAMPLES_DIR / f"{environment_name}.json"
    made = generate(read_json(problem_file), layout_seed)
    built = build_problem(load_domain(root), made.problem, str(problem_file))
    return {
        "environment_name": environment_name,
        "seed": layout_seed,
        "used_seed": made.used_seed,
        "noisy_randomization": False,
        "optimal_steps": optimal_steps,
        "max_steps": None if optimal_steps is None else optimal_steps * UPSTREAM_STEP_MULTIPLIER,
        "generated_environment_json": made.problem,
        "initial_observation": built.state.observation(built.goal_description),
        "num_objects": len(built.state.types),
        "num_goal_sets": built.goal.count_assignments(),
        "generated_by": GENERATED_BY,
    }


def write_instances(root: Path, dest: Path) -> list[str]:
    """Write the 200 benchmark instances and the 2 demonstration ones, each folder with a
    ``summary.json`` and a ``README.md``, under ``dest`` (usually ``root``); returns the relative
    paths written. The bytes depend only on the problem files, the domain and this code, so
    ``recap data`` pins their sha256 (``pipeline/manifests/robotouille-generated.sha256``)."""
    written: list[str] = []
    benchmark = [
        (f"{split}/{task}", seed, catalog.OPTIMAL_STEPS[split][task])
        for split in catalog.SPLITS
        for task in catalog.tasks(split)
        for seed in catalog.LAYOUT_SEEDS
    ]
    train = [(f"{split}/{task}", TRAIN_SEED, None) for split, task in TRAIN_KITCHENS]
    for folder, wanted in (("instances", benchmark), ("instances_train", train)):
        rows = []
        for environment_name, seed, optimal in wanted:
            record = instance_record(root, environment_name, seed, optimal)
            rel = f"{folder}/{environment_name}_{seed}.json"
            _write(dest / rel, json.dumps(record, indent=1))
            written.append(rel)
            rows.append({k: record[k] for k in ("environment_name", "seed", "used_seed", "num_objects", "num_goal_sets")})
        _write(dest / folder / "summary.json", json.dumps(rows, indent=1))
        _write(dest / folder / "README.md", _README.format(count=len(wanted)))
        written += [f"{folder}/summary.json", f"{folder}/README.md"]
    return written


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")


_README = """# Robotouille instances generated by recap-eval

{count} instance files, one per (environment, seed): `<split>/<task>_<seed>.json`. They were
written by `recap data fetch robotouille` with recap-eval's re-implementation of the real
engine's seeded kitchen generator (`workers/envs/robotouille/generator.py`), which reproduces the
real engine's `generated_environment_json` and `used_seed` exactly for every benchmark instance.

Fields: environment_name, seed, used_seed (the first seed from `seed` on whose generation
succeeded), noisy_randomization (always false), optimal_steps and max_steps (1.5 x optimal, as in
Robotouille's own configs; null for the demonstration kitchens), generated_environment_json (feed
this to the engine), initial_observation and num_goal_sets (computed by recap-eval's engine),
num_objects, generated_by. summary.json: one row per instance, without the big fields.
"""
