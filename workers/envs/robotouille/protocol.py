"""How the methods run on Robotouille: what the ``paper`` and ``released`` profiles and the
authors' released prompts mean here, declared by the benchmark (recap.config.BenchmarkProtocol).

Read from GitHub ``ReCAP-Stanford/ReCAP`` at 2fb112f (``robotouille-baselines``): every released
Robotouille baseline is run with the benchmark's own ReAct protocol and samples at 0.7, and the
released prompts ask for the labelled plain-text replies (or, for ADaPT, the released algorithm).
"""

from __future__ import annotations

from typing import Any

from recap.baselines.act import ActConfig
from recap.baselines.adapt import ADaPTConfig
from recap.baselines.cot import PlanConfig
from recap.baselines.react import ReActConfig
from recap.baselines.reply_format import RELEASED_TEXT
from recap.config import AgentConfig

#: what the released Robotouille baselines sample at (robotouille-baselines/conf/llm/base_llm.yaml:2,
#: sent by agents/prompt_builder/prompt_llm.py:140-144)
RELEASED_BASELINE_TEMPERATURE = 0.7

#: the benchmark's ReAct with the "original" prompt, as every released main config runs it
#: (robotouille-baselines/conf/experiments/ReAct/{synchronous,asynchronous}/original_*.yaml:
#: prompt_description original, every is_*_history flag false): the whole history, trimmed once
#: it passes 64 messages by dropping the oldest pair after the first exchange
#: (agents/ReAct_agent.py:129-130), 2 messages on a context-length error (:138); after 5
#: consecutive invalid actions a new round of feedback, the third round ends the episode
#: (:62-64, :284-288)
REACT: dict[str, Any] = {
    "history": "window",
    "window": 64,
    "window_counts_pins": False,
    "window_keeps_first": True,
    "context_drop": 2,
    "invalid_streak": 5,
    "invalid_rounds": 3,
}


def profile_settings(config_cls: type[AgentConfig], profile: str, generic: dict[str, Any]) -> dict[str, Any]:
    """The profile's settings on Robotouille for a method with config class ``config_cls``
    (:meth:`recap.config.BenchmarkProtocol.profile_settings`)."""
    out: dict[str, Any] = {}
    if profile == "paper":
        # Robotouille observations are the whole kitchen plus its valid actions (~3.5K
        # characters); repeating them after each of the example's 22 actions pins ~20K tokens
        # into every call. The paper's one-shot example follows the benchmark's demonstration
        # with the observations left out; we keep the first one so the example's reasoning
        # can be checked against the state it starts from.
        out["demo_observations"] = "first"
    if profile == "released":
        # every released Robotouille baseline (ReAct, Act, ADaPT, I/O, I/O-CoT) samples at the
        # base config's temperature; ReCAP's own profile overrides it (its calls send none)
        out["temperature"] = RELEASED_BASELINE_TEMPERATURE
    out.update(generic)
    if issubclass(config_cls, ReActConfig):
        out.update(REACT)
    if issubclass(config_cls, ActConfig):
        # the released Act has its 64-message trim commented out (robotouille-baselines/
        # agents/Act_agent.py:129-131): no window, the oldest pair after the first exchange
        # dropped only on a context-length error (:137-138)
        out.update(history="all", window_keeps_first=True)
        # no window of its own: ``window`` stays the profile's, unused, rather than ReAct's
        # 64 (reports show one window per method and benchmark)
        out.pop("window", None)
    return out


def release_prompt_settings(config_cls: type[AgentConfig]) -> dict[str, Any]:
    """What the released Robotouille prompts imply: the labelled "Reasoning:" / "Action:" lines
    (ReAct/1.0.0-original.yml, Act/1.0.0-original.yml), the I/O agents' plain-text plan
    (IO/1.0.0-io.yml, IO/1.1.0-io-cot.yml), ADaPT's released algorithm (a planner and ReAct
    executors in plain text, ADaPT_agent.py); ReCAP's prompt implies nothing."""
    if issubclass(config_cls, ADaPTConfig):
        return {"algorithm": "plan_once", "json_mode": False}
    if issubclass(config_cls, (ReActConfig, PlanConfig)):
        return dict(RELEASED_TEXT)
    return {}
