"""The registry of agent methods: name -> (agent class, config class), and one way to build an
agent from a method name, a profile, an ablation and explicit settings.

The pipeline names methods in run specs (``method: react``); this is the single place that maps
those names to code, so an unknown name fails the same way everywhere.
"""

from __future__ import annotations

from typing import Any

from recap.agent import Agent
from recap.baselines import (
    ActAgent,
    ADaPTAgent,
    ADaPTConfig,
    CoTAgent,
    PlanConfig,
    ReActAgent,
    ReActConfig,
    StandardAgent,
)
from recap.config import AgentConfig, ConfigError, ReCAPConfig, build_config
from recap.recap_agent import ReCAPAgent

METHODS: dict[str, tuple[type[Agent], type[AgentConfig]]] = {
    "recap": (ReCAPAgent, ReCAPConfig),
    "react": (ReActAgent, ReActConfig),
    "act": (ActAgent, ReActConfig),
    "cot": (CoTAgent, PlanConfig),
    "standard": (StandardAgent, PlanConfig),
    "adapt": (ADaPTAgent, ADaPTConfig),
}


def method_classes(method: str) -> tuple[type[Agent], type[AgentConfig]]:
    if method not in METHODS:
        raise ConfigError(f"unknown method {method!r}; known: {', '.join(METHODS)}")
    return METHODS[method]


def make_agent(method: str, profile: str | None = None, ablation: str | None = None,
               benchmark: str | None = None, **settings: Any) -> Agent:
    """Profile defaults (for ``benchmark`` when given), then the ablation, then explicit
    settings (see ``build_config``)."""
    agent_cls, config_cls = method_classes(method)
    return agent_cls(build_config(config_cls, profile, ablation, benchmark, **settings))
