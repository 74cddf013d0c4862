"""Act (act-only prompting): ReAct without the thought, one action per reply ``{"action"}``.

Everything else — pins, observations, error feedback, window, caps — is ReAct's.
"""

from __future__ import annotations

from recap.baselines import prompts as P
from recap.baselines.react import ReActAgent, ReActConfig

__all__ = ["ActAgent", "ReActConfig"]


class ActAgent(ReActAgent):
    """Act: ReAct without the thought; each reply names the next action alone."""

    style = "act"
    expected_format = P.action_format(False)
    with_think = False
    reply_fields = ("action",)
