"""Build an agent from a method name, a profile, an ablation and explicit settings; register
and unregister methods.

The pipeline names methods in run specs (``method: react``); :data:`METHODS` (kept in
:mod:`recap.method_registry`, below the agents, so the demonstrations can read it too) maps
those names to code, so an unknown name fails the same way everywhere.

Everything else about a method is declared by its agent class (reply fields for the offline
test doubles, demonstration replies derived from a benchmark's script, call-cap and estimate
assumptions), so a new method is its module, its prompts, its tests and one registration: for a
built-in, one line in the table of :mod:`recap.method_registry`; for a plug-in, one
:func:`register_method` call. That table is the one list of method names: nothing else lists
them (``schemas.labels.VERSION_1_METHODS`` is the frozen vocabulary of old rows, not a copy).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from recap.agent import Agent
from recap.config import AgentConfig, BenchmarkProtocol, ConfigError, build_config
from recap.method_registry import METHODS, Method, check_method

__all__ = ["METHODS", "Method", "register_method", "unregister_method", "registered_method", "method_classes", "make_agent"]


def register_method(name: str, agent_cls: type[Agent], config_cls: type[AgentConfig]) -> None:
    """Make ``name`` a method: run specs, workers and demonstrations then find it like a built-in.

    The agent class's ``style`` must be ``name`` (its key for demonstration replies and the
    hints), and ``config_cls`` must be the agent's own config class or a subclass of it."""
    if name in METHODS:
        raise ConfigError(f"method {name!r} is already registered")
    if not (isinstance(agent_cls, type) and issubclass(agent_cls, Agent)):
        raise ConfigError(f"method {name!r}: {agent_cls!r} is not an Agent subclass")
    METHODS.register(name, check_method(name, agent_cls, config_cls))


def unregister_method(name: str) -> None:
    """Undo :func:`register_method` (for tests and plug-ins that go away)."""
    METHODS.unregister(name)


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
    agent_cls, config_cls = METHODS.get(method)
    if not issubclass(agent_cls, Agent):  # a class registered without register_method's check
        raise ConfigError(f"method {method!r}: {agent_cls!r} is not an Agent subclass")
    return agent_cls, config_cls


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
