"""Agent settings: one dataclass per method, ablations as fields, and the two named profiles.

Ablations are configuration of one agent, never copies of it. ``paper`` follows the paper
(K = 64 messages, temperature 0.5); ``released`` follows the authors' released code (K = 128,
temperature not sent, so the provider default applies).
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from typing import Any, Literal

PROFILES: dict[str, dict[str, Any]] = {
    "paper": {"window": 64, "temperature": 0.5},
    "released": {"window": 128, "temperature": None},
}


class ConfigError(ValueError):
    """An unknown or out-of-range agent setting."""


@dataclass(frozen=True)
class AgentConfig:
    """Settings every agent shares: the window, generation settings and per-episode caps."""

    window: int = 64
    window_mode: Literal["pair", "block"] = "pair"
    window_block: int | None = None
    temperature: float | None = 0.5
    max_tokens: int | None = None
    json_mode: bool = True
    max_json_repairs: int = 3
    max_llm_calls: int = 400
    max_episode_tokens: int | None = None
    max_episode_cost_usd: float | None = None
    context_drop: int = 32

    def validate(self) -> None:
        if self.window < 2:
            raise ConfigError(f"window must be >= 2 messages, got {self.window}")
        if self.window_mode not in ("pair", "block"):
            raise ConfigError(f"window_mode must be 'pair' or 'block', got {self.window_mode!r}")
        if self.temperature is not None and not 0 <= self.temperature <= 2:
            raise ConfigError(f"temperature must be in [0, 2], got {self.temperature}")
        if self.max_json_repairs < 0:
            raise ConfigError("max_json_repairs must be >= 0")
        if self.max_llm_calls < 1:
            raise ConfigError("max_llm_calls must be >= 1")
        if self.context_drop < 2:
            raise ConfigError("context_drop must be >= 2")

    def to_json(self) -> str:
        """Canonical JSON (sorted keys): part of a unit's content hash and of episode rows."""
        return json.dumps(dataclasses.asdict(self), sort_keys=True)


@dataclass(frozen=True)
class ReCAPConfig(AgentConfig):
    """ReCAP settings. ``max_level`` caps the tree (root = level 1; the paper's level_2..5);
    ``think`` is ``latest`` (paper), ``none`` (no_think) or ``many`` (think_many);
    ``name_only`` makes return prompts carry only the finished and the current task."""

    max_level: int | None = None
    think: Literal["latest", "none", "many"] = "latest"
    name_only: bool = False
    reminder_period: int | None = 10
    shortcut: bool = True

    def validate(self) -> None:
        super().validate()
        if self.max_level is not None and self.max_level < 2:
            raise ConfigError(f"max_level must be >= 2 (root is level 1), got {self.max_level}")
        if self.think not in ("latest", "none", "many"):
            raise ConfigError(f"think must be latest, none or many, got {self.think!r}")
        if self.reminder_period is not None and self.reminder_period < 1:
            raise ConfigError("reminder_period must be >= 1 or null")


#: the paper's ablation names, as settings of ReCAPConfig
ABLATIONS: dict[str, dict[str, Any]] = {
    "original": {},
    "no_think": {"think": "none"},
    "think_many": {"think": "many"},
    "name_only": {"name_only": True},
    "level_2": {"max_level": 2},
    "level_3": {"max_level": 3},
    "level_4": {"max_level": 4},
    "level_5": {"max_level": 5},
    "no_shortcut": {"shortcut": False},
}


def build_config(cls: type[AgentConfig], profile: str | None = None, ablation: str | None = None, **overrides: Any) -> AgentConfig:
    """Profile defaults, then an ablation, then explicit overrides; unknown names are errors."""
    values: dict[str, Any] = {}
    if profile is not None:
        if profile not in PROFILES:
            raise ConfigError(f"unknown profile {profile!r}; known: {', '.join(PROFILES)}")
        values.update(PROFILES[profile])
    if ablation is not None:
        if ablation not in ABLATIONS:
            raise ConfigError(f"unknown ablation {ablation!r}; known: {', '.join(ABLATIONS)}")
        if cls is not ReCAPConfig and ABLATIONS[ablation]:
            raise ConfigError(f"ablation {ablation!r} applies to recap only")
        values.update(ABLATIONS[ablation])
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(overrides) - names)
    if unknown:
        raise ConfigError(f"unknown setting(s) {', '.join(unknown)} for {cls.__name__}; known: {', '.join(sorted(names))}")
    values.update(overrides)
    cfg = cls(**values)
    cfg.validate()
    return cfg
