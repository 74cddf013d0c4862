"""The registry of agent methods: name -> (agent class, config class), and one way to build an
agent from a method name, a profile, an ablation and explicit settings.

The pipeline names methods in run specs (``method: react``); this is the single place that maps
those names to code, so an unknown name fails the same way everywhere.

Everything else about a method is declared by its agent class (reply fields for the offline
test doubles, demonstration replies derived from a benchmark's script, call-cap and estimate
assumptions), so a new method is its module, its prompts, its tests and one
:func:`register_method` call (for a built-in: one line in :data:`METHODS`). This table is the
one list of method names: nothing else lists them (``schemas.labels.VERSION_1_METHODS`` is the
frozen vocabulary of old rows, not a copy).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from recap.agent import Agent
from recap.baselines import (
    ActAgent,
    ActConfig,
    ADaPTAgent,
    ADaPTConfig,
    CoTAgent,
    PlanConfig,
    ReActAgent,
    ReActConfig,
    StandardAgent,
)
from recap.config import AgentConfig, BenchmarkProtocol, ConfigError, ReCAPConfig, build_config
from recap.demo_script import register_deriver, unregister_deriver
from recap.recap_agent import ReCAPAgent

METHODS: dict[str, tuple[type[Agent], type[AgentConfig]]] = {
    "recap": (ReCAPAgent, ReCAPConfig),
    "react": (ReActAgent, ReActConfig),
    "act": (ActAgent, ActConfig),
    "cot": (CoTAgent, PlanConfig),
    "standard": (StandardAgent, PlanConfig),
    "adapt": (ADaPTAgent, ADaPTConfig),
}
for _agent_cls, _ in METHODS.values():
    register_deriver(_agent_cls.style, _agent_cls)


def register_method(name: str, agent_cls: type[Agent], config_cls: type[AgentConfig]) -> None:
    """Make ``name`` a method: run specs, workers and demonstrations then find it like a built-in.

    The agent class's ``style`` must be ``name`` (its key for demonstration replies and the
    hints), and ``config_cls`` must be the agent's own config class or a subclass of it."""
    if name in METHODS:
        raise ConfigError(f"method {name!r} is already registered")
    if not (isinstance(agent_cls, type) and issubclass(agent_cls, Agent)):
        raise ConfigError(f"method {name!r}: {agent_cls!r} is not an Agent subclass")
    if getattr(agent_cls, "style", None) != name:
        raise ConfigError(f"method {name!r}: {agent_cls.__name__}.style must be {name!r}")
    if not (isinstance(config_cls, type) and issubclass(config_cls, agent_cls.config_cls)):
        raise ConfigError(f"method {name!r}: {config_cls!r} is not a {agent_cls.config_cls.__name__}")
    METHODS[name] = (agent_cls, config_cls)
    register_deriver(name, agent_cls)


def unregister_method(name: str) -> None:
    """Undo :func:`register_method` (for tests and plug-ins that go away)."""
    if name not in METHODS:
        raise ConfigError(f"method {name!r} is not registered")
    del METHODS[name]
    unregister_deriver(name)


@contextmanager
def registered_method(name: str, agent_cls: type[Agent], config_cls: type[AgentConfig]) -> Iterator[None]:
    """:func:`register_method` for the duration of a ``with`` block."""
    register_method(name, agent_cls, config_cls)
    try:
        yield
    finally:
        unregister_method(name)


def method_classes(method: str) -> tuple[type[Agent], type[AgentConfig]]:
    """The (agent class, config class) registered as ``method``; raises ConfigError naming the known
    methods."""
    if method not in METHODS:
        raise ConfigError(f"unknown method {method!r}; known: {', '.join(METHODS)}")
    return METHODS[method]


def make_agent(
    method: str,
    profile: str | None = None,
    ablation: str | None = None,
    benchmark: BenchmarkProtocol | None = None,
    **settings: Any,
) -> Agent:
    """Profile defaults (as ``benchmark``, a benchmark's protocol object, declares them when
    given), then the ablation, then explicit settings (see ``build_config``)."""
    agent_cls, config_cls = method_classes(method)
    return agent_cls(build_config(config_cls, profile, ablation, benchmark, **settings))
