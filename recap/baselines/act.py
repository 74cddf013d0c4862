"""Act (act-only prompting): ReAct without the thought, one action per reply ``{"action"}``.

Everything else — pins, observations, error feedback, caps — is ReAct's. The window is not: the
released Act keeps its whole history on both benchmarks (``history: all`` under the profiles).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from recap.baselines import prompts as P
from recap.baselines.react import ReActAgent, ReActConfig

__all__ = ["ActAgent", "ActConfig", "ReActConfig"]


@dataclass(frozen=True)
class ActConfig(ReActConfig):
    """Act settings: ReAct's, with the released Act's history under the profiles and its reply
    format under ``released``: on ALFWorld the released Act asks for JSON
    (alfworld-recap/act_alfworld/act.py:165-168, ``response_format`` json_object), so
    ``released`` keeps ``reply_format: json`` there (Robotouille's Act: the labelled text)."""

    released_text = False

    @classmethod
    def profile_defaults(cls, profile: str, benchmark: str | None, ablation: str | None) -> dict[str, Any]:
        out = super().profile_defaults(profile, benchmark, ablation)
        if benchmark == "robotouille":
            # the released Act has its 64-message trim commented out (robotouille-baselines/
            # agents/Act_agent.py:129-131): no window, the oldest pair after the first exchange
            # dropped only on a context-length error (:137-138)
            out.update(history="all", window_keeps_first=True)
            # no window of its own: ``window`` stays the profile's, unused, rather than ReAct's
            # 64 (reports show one window per method and benchmark)
            out.pop("window", None)
        elif benchmark == "alfworld":
            # alfworld-recap/act_alfworld/act.py:50-71 never trims; 32 messages go on a
            # context-length error (:74-77)
            out.update(history="all")
            if profile == "released":
                # no JSON repair: a malformed reply becomes a command the game answers
                # (act.py:181-199, recap.baselines.act_json)
                out["malformed_json"] = "game"
        return out


class ActAgent(ReActAgent):
    """Act: ReAct without the thought; each reply names the next action alone."""

    style = "act"
    # ReActConfig (ActAgent(ReActConfig(...)) stays valid); the registry resolves "act" with
    # ActConfig, whose profile_defaults hold the released Act's history
    expected_format = P.action_format(False)
    with_think = False
    reply_fields = ("action",)
