"""Act (act-only prompting): ReAct without the thought, one action per reply ``{"action"}``.

Everything else — pins, observations, error feedback, window, caps — is ReAct's.
"""

from __future__ import annotations

from dataclasses import dataclass

from recap.baselines import prompts as P
from recap.baselines.react import ReActAgent, ReActConfig

__all__ = ["ActAgent", "ActConfig", "ReActConfig"]


@dataclass(frozen=True)
class ActConfig(ReActConfig):
    """ReAct's settings; only the released profile differs: on ALFWorld the released Act asks for
    JSON (alfworld-recap/act_alfworld/act.py:165-168, ``response_format`` json_object), so
    ``released`` keeps ``reply_format: json`` there."""

    released_text = False


class ActAgent(ReActAgent):
    """Act: ReAct without the thought; each reply names the next action alone."""

    style = "act"
    expected_format = P.action_format(False)
    with_think = False
    reply_fields = ("action",)
