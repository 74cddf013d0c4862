"""The 200 benchmark instances: ids, selectors and optimal step counts.

An instance id is ``robotouille/<split>/<task>@<layout seed>`` (the kitchen's layout seed). The list is fixed by the benchmark (10
synchronous + 10 asynchronous tasks x layout seeds 42, 84, ..., 420) and needs no data folder, so
selections can be made before any data is mounted. ``asynchronous/3.1_lettuce_cheeseburger`` ships
with the problems but is in no benchmark list, so it is not an instance.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from workers.envs.registry import UnknownInstanceError

BENCHMARK_NAME = "robotouille"
SPLITS = ("synchronous", "asynchronous")
#: the kitchens' layout seeds (the ``@N`` of an instance id)
LAYOUT_SEEDS = tuple(42 * k for k in range(1, 11))

#: optimal step counts per task (the benchmark's experiment configs)
OPTIMAL_STEPS: dict[str, dict[str, int]] = {
    "synchronous": {
        "0_cheese_sandwich": 10,
        "1_lettuce_sandwich": 14,
        "2_lettuce_tomato_sandwich": 24,
        "3_burger": 10,
        "4_cheeseburger": 15,
        "5_double_cheeseburger": 23,
        "6_lettuce_tomato_cheeseburger": 36,
        "7_two_lettuce_chicken_sandwich": 44,
        "8_two_lettuce_tomato_burger": 63,
        "9_onion_cheese_burger_and_lettuce_tomato_chicken_sandwich": 57,
    },
    "asynchronous": {
        "0_cheese_chicken_sandwich": 21,
        "1_lettuce_chicken_sandwich": 27,
        "2_lettuce_tomato_fried_chicken_sandwich": 37,
        "3_tomato_burger_and_fries": 42,
        "4_onion_cheese_burger_and_fried_onion": 46,
        "5_potato_soup": 19,
        "6_onion_soup": 42,
        "7_tomato_soup_and_lettuce_chicken_sandwich": 46,
        "8_onion_tomato_soup_and_two_chicken_sandwich": 68,
        "9_onion_potato_soup_and_fried_onion_ring_lettuce_burger_and_onion_cheese_sandwich": 82,
    },
}

_ID = re.compile(r"^(?P<split>[a-z]+)/(?P<task>[0-9A-Za-z_.]+)@(?P<seed>-?\d+)$")


@dataclass(frozen=True)
class InstanceRef:
    """One benchmark instance (split, task, the kitchen's layout seed), the parsed form of an instance id."""

    split: str
    task: str
    layout_seed: int

    @property
    def instance_id(self) -> str:
        """The instance's id, ``robotouille/<split>/<task>@<layout seed>``."""
        return f"{BENCHMARK_NAME}/{self.split}/{self.task}@{self.layout_seed}"

    @property
    def optimal_steps(self) -> int:
        """The optimal number of steps of the instance's task (the step cap is a multiple of it)."""
        return OPTIMAL_STEPS[self.split][self.task]


def _task_number(task: str) -> float:
    return float(task.split("_", 1)[0])


def tasks(split: str) -> list[str]:
    """The benchmark tasks of ``split``, ordered by task number (2 before 10); KeyError for an unknown split."""
    return sorted(OPTIMAL_STEPS[split], key=_task_number)


def all_refs() -> list[InstanceRef]:
    """Every instance of the benchmark (both splits, every task, every layout seed), in the catalog's fixed order."""
    return [InstanceRef(split, task, seed) for split in SPLITS for task in tasks(split) for seed in LAYOUT_SEEDS]


def _strip_prefix(text: str) -> str:
    prefix = BENCHMARK_NAME + "/"
    return text[len(prefix) :] if text.startswith(prefix) else text


def parse_id(instance_id: str) -> InstanceRef:
    """The instance an id names; UnknownInstanceError (saying what exists) otherwise."""
    match = _ID.match(_strip_prefix(instance_id))
    if not match:
        raise UnknownInstanceError(
            f"unknown Robotouille instance {instance_id!r}: ids look like "
            f"robotouille/<{'|'.join(SPLITS)}>/<task>@<seed>, e.g. robotouille/asynchronous/5_potato_soup@42"
        )
    split, task, seed = match["split"], match["task"], int(match["seed"])
    if split not in OPTIMAL_STEPS:
        raise UnknownInstanceError(f"unknown Robotouille split {split!r} in {instance_id!r}; splits: {', '.join(SPLITS)}")
    if task not in OPTIMAL_STEPS[split]:
        raise UnknownInstanceError(
            f"unknown Robotouille task {split}/{task!r} in {instance_id!r}; tasks: {', '.join(tasks(split))}"
        )
    if seed not in LAYOUT_SEEDS:
        raise UnknownInstanceError(
            f"unknown layout seed {seed} in {instance_id!r}; layout seeds: {', '.join(map(str, LAYOUT_SEEDS))}"
        )
    return InstanceRef(split, task, seed)


def select(selector: str | None = None) -> list[InstanceRef]:
    """Instances a selector names, in benchmark order (split, task number, layout seed).

    ``None``/``""``/``all``/``robotouille``: all 200; ``<split>``; ``<split>/<task number>`` or
    ``<split>/<task name>`` (10 seeds); a full id (one instance).
    """
    refs = all_refs()
    text = _strip_prefix((selector or "").strip()).strip("/")
    if text in ("", "all", BENCHMARK_NAME):
        return refs
    if "@" in text:
        return [parse_id(text)]
    split, _, task = text.partition("/")
    if split not in OPTIMAL_STEPS:
        raise UnknownInstanceError(f"unknown Robotouille selector {selector!r}: splits are {', '.join(SPLITS)}")
    if not task:
        return [r for r in refs if r.split == split]
    names = tasks(split)
    chosen = [t for t in names if t == task or t.split("_", 1)[0] == task]
    if len(chosen) != 1:
        raise UnknownInstanceError(
            f"unknown Robotouille task {split}/{task!r} in selector {selector!r}; tasks: {', '.join(names)}"
        )
    return [r for r in refs if r.split == split and r.task == chosen[0]]
