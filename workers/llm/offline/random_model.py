"""TEST DOUBLE ``offline/random``: a random valid action in the agent's reply format.

Why: a lower bound for success rates and a stress test of long episodes (step caps, context
trimming) at no cost. The choice depends only on (seed, call_key), like every offline model.
When the action space is open (``valid_actions`` is None) it answers ``look``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from workers.llm.offline.knobs import Knobs, call_rng

OPEN_SPACE_ACTION = "look"


def random_reply(hints: Mapping[str, Any], knobs: Knobs, call_key: str) -> dict[str, Any]:
    style = str(hints.get("style", "recap"))
    valid = list(hints.get("valid_actions") or [])
    action = call_rng(call_key, knobs.seed, "random").choice(valid) if valid else OPEN_SPACE_ACTION
    think = "Picking an action at random."
    if style == "recap" or (style == "adapt" and "plan" in str(hints.get("purpose", ""))):
        return {"think": think, "subtasks": [action]}
    if style == "act":
        return {"action": action}
    if style in ("react", "adapt"):
        return {"think": think, "action": action}
    if style == "standard":
        return {"actions": [action]}
    if style == "cot":
        return {"think": think, "actions": [action]}
    raise ValueError(f"offline/random: unknown style {style!r}")
