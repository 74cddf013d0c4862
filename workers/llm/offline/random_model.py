"""TEST DOUBLE ``offline/random``: a random valid action in the reply fields the agent asks for
(``hints["reply_fields"]``, see :mod:`workers.llm.offline.expert`).

Why: a lower bound for success rates and a stress test of long episodes (step caps, context
trimming) at no cost. The choice depends only on (noise_seed, call_key), like every offline model.
When the action space is open (``valid_actions`` is None) it answers ``look``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from workers.llm.offline.expert import FIELDS, reply_fields_of
from workers.llm.offline.knobs import Knobs, call_rng

OPEN_SPACE_ACTION = "look"


def random_reply(hints: Mapping[str, Any], knobs: Knobs, call_key: str) -> dict[str, Any]:
    """Every field the agent asked for holds the one random action (``think`` a fixed text)."""
    valid = list(hints.get("valid_actions") or [])
    action = call_rng(call_key, knobs.noise_seed, "random").choice(valid) if valid else OPEN_SPACE_ACTION
    reply: dict[str, Any] = {}
    for name in reply_fields_of(hints):
        if name == "think":
            reply[name] = "Picking an action at random."
        elif name == "action":
            reply[name] = action
        elif name in ("subtasks", "actions"):
            reply[name] = [action]
        else:
            raise ValueError(f"offline/random: cannot fill reply field {name!r}; it fills {', '.join(FIELDS)}")
    return reply
