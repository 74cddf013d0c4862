"""The six ALFWorld task types and the short names users select them by.

ALFRED names task types by long identifiers (``pick_heat_then_place_in_recep``); selectors,
instance ids and demonstrations use the short names the paper's tables use (``heat``). Keeping the
one table here means games, ids and demonstrations cannot disagree about the mapping.
"""

from __future__ import annotations

#: short name -> ALFRED task type, in the order the paper lists them
TASK_TYPES: dict[str, str] = {
    "put": "pick_and_place_simple",
    "clean": "pick_clean_then_place_in_recep",
    "heat": "pick_heat_then_place_in_recep",
    "cool": "pick_cool_then_place_in_recep",
    "examine": "look_at_obj_in_light",
    "puttwo": "pick_two_obj_and_place",
}

#: ALFRED task type -> short name
SHORT_NAMES: dict[str, str] = {long: short for short, long in TASK_TYPES.items()}


def short_name(task_type: str) -> str:
    """The short name of an ALFRED task type (``pick_cool_then_place_in_recep`` -> ``cool``)."""
    try:
        return SHORT_NAMES[task_type]
    except KeyError:
        raise ValueError(f"unknown ALFWorld task type {task_type!r}; known: {', '.join(SHORT_NAMES)}") from None
