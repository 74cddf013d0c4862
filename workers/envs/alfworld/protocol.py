"""How the methods run on ALFWorld: what the ``paper`` and ``released`` profiles and the
authors' released prompts mean here, declared by the benchmark (recap.config.BenchmarkProtocol).

Read from GitHub ``ReCAP-Stanford/ReCAP`` at 2fb112f (``alfworld-recap``): ReAct and Act follow
Yao et al.'s released scripts (react_alfworld/react.py, act_alfworld/act.py), ReCAP's released
code sends no rules reminder, and the release has no I/O (CoT, Standard) or ADaPT agent here, so
those keep our JSON replies and the paper's algorithm under ``released``.
"""

from __future__ import annotations

from typing import Any

from recap.baselines.act import ActConfig
from recap.baselines.adapt import RELEASED_PLAN_ONCE, ADaPTConfig
from recap.baselines.cot import PlanConfig
from recap.baselines.react import ReActConfig
from recap.baselines.reply_format import RELEASED_TEXT
from recap.config import AgentConfig, ReCAPConfig

#: alfworld-recap/react_alfworld/react.py: the valid actions after the first observation (:209)
#: and every valid action's observation (:172), "OK." for a thought (:159-160), the explained
#: feedback after an invalid command (:161-170); 128 messages counted over the whole history,
#: oldest pair dropped (:51-52), 32 on a context-length error (:69); Yao et al.'s example has no
#: valid-action lists (:206-208)
REACT: dict[str, Any] = {
    "history": "window",
    "window": 128,
    "window_counts_pins": True,
    "context_drop": 32,
    "invalid_streak": None,
    "think_actions": True,
    "invalid_feedback": "explained",
    "valid_actions": "episode",
}
#: the released ReAct's one-line replies ("think: ..." or the command, react.py:152-160)
REACT_TEXT: dict[str, Any] = {**RELEASED_TEXT, "text_layout": "yao"}


def _without(settings: dict[str, Any], dropped: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in settings.items() if k not in dropped}


def profile_settings(config_cls: type[AgentConfig], profile: str, generic: dict[str, Any]) -> dict[str, Any]:
    """The profile's settings on ALFWorld for a method with config class ``config_cls``
    (:meth:`recap.config.BenchmarkProtocol.profile_settings`)."""
    released = profile == "released"
    out = dict(generic)
    if issubclass(config_cls, ReCAPConfig) and released:
        out["reminder_period"] = None  # the released ALFWorld code has no reminder
    if issubclass(config_cls, ReActConfig):
        out.update(REACT)
    if issubclass(config_cls, ActConfig):
        # alfworld-recap/act_alfworld/act.py:50-71 never trims; 32 messages go on a
        # context-length error (:74-77)
        out["history"] = "all"
        if released:
            # JSON, as act.py:165-168 asks (``response_format`` json_object), and no JSON repair:
            # a malformed reply becomes a command the game answers (act.py:181-199,
            # recap.baselines.act_json)
            out = _without(out, RELEASED_TEXT)
            out["malformed_json"] = "game"
    elif issubclass(config_cls, ReActConfig) and released:
        out.update(REACT_TEXT)
    if issubclass(config_cls, PlanConfig) and released:
        out = _without(out, RELEASED_TEXT)  # no released I/O agent here: our JSON plan
    if issubclass(config_cls, ADaPTConfig) and released:
        out = _without(out, RELEASED_PLAN_ONCE)  # no released ADaPT here: the paper's algorithm
    return out


def release_prompt_settings(config_cls: type[AgentConfig]) -> dict[str, Any]:
    """What the released ALFWorld prompts imply: ReAct's one line (react_alfworld/react.py),
    Act's JSON (act_alfworld/act.py:165-168), no rules reminder for ReCAP (alfworld-recap/MATRIX/
    MATRIX/chatbot.py sends none); no released prompts for the other methods."""
    if issubclass(config_cls, ActConfig):
        return {"reply_format": "json"}
    if issubclass(config_cls, ReActConfig):
        return dict(REACT_TEXT)
    if issubclass(config_cls, ReCAPConfig):
        return {"reminder_period": None}
    return {}
