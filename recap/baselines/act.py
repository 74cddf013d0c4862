"""Act (act-only prompting): ReAct without the thought, one action per reply ``{"action"}``.

Everything else — pins, observations, error feedback, caps — is ReAct's. The window is not: the
released Act keeps its whole history on both benchmarks (``history: all`` under the profiles).
"""

from __future__ import annotations

from dataclasses import dataclass

from recap.baselines import prompts as P
from recap.baselines.react import ReActAgent, ReActConfig

__all__ = ["ActAgent", "ActConfig", "ReActConfig"]


@dataclass(frozen=True)
class ActConfig(ReActConfig):
    """Act settings: ReAct's, with the released Act's history under the profiles and its reply
    format under ``released``: on ALFWorld the released Act asks for JSON
    (alfworld-recap/act_alfworld/act.py:165-168, ``response_format`` json_object), so
    ``released`` keeps ``reply_format: json`` there (Robotouille's Act: the labelled text). Both
    items, and the released Act's whole-history window, are the benchmarks' declarations
    (``workers/envs/<benchmark>/protocol.py``)."""


class ActAgent(ReActAgent):
    """Act: ReAct without the thought; each reply names the next action alone."""

    style = "act"
    # ReActConfig (ActAgent(ReActConfig(...)) stays valid); the registry resolves "act" with
    # ActConfig, whose profile_defaults hold the released Act's history
    expected_format = P.action_format(False)
    with_think = False
    reply_fields = ("action",)
