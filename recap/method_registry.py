"""The method registry: every method's name and where its agent and config classes are defined.

Why here and not in :mod:`recap.methods`: the demonstrations (:mod:`recap.demo_replies`, which
:mod:`recap.env` uses) derive each method's replies from the registered agent classes, and the
agents import the environment interface, so the registry must sit below the agents. It names
them by reference (``"recap.baselines:ReActAgent"``, imported on first use) and reads of a
class only what :class:`MethodClass` declares; :mod:`recap.methods` builds agents from it.

The built-in methods are the table at the end of this module: one line each, the one list of
method names (``schemas.labels.VERSION_1_METHODS`` is the frozen vocabulary of old rows, not a
copy). A plug-in registers with :func:`recap.methods.register_method`.
"""

from __future__ import annotations

from typing import Any, ClassVar, NamedTuple, Protocol

from recap.config import AgentConfig, ConfigError
from recap.demo_script import DemoScript
from recap.registry import Registry, import_reference


class MethodClass(Protocol):
    """What the registry and the demonstrations read of a method's agent class (every
    :class:`recap.agent.Agent` subclass has it)."""

    style: ClassVar[str]
    config_cls: ClassVar[type[AgentConfig]]

    @classmethod
    def demo_replies(cls, script: DemoScript) -> list[dict[str, Any]] | None:
        """This method's replies to the demonstration ``script`` (None: it derives none)."""


class Method(NamedTuple):
    """A registered method: the agent class and the config class its settings are built as."""

    agent_cls: type[MethodClass]
    config_cls: type[AgentConfig]


def check_method(name: str, agent_cls: object, config_cls: object) -> Method:
    """``Method(agent_cls, config_cls)`` when they fit ``name``; raises ConfigError naming what
    does not: the class's ``style`` must be ``name`` (its key for demonstration replies and the
    hints), and the config class must be the agent's own config class or a subclass of it."""
    if not isinstance(agent_cls, type) or not hasattr(agent_cls, "config_cls"):
        raise ConfigError(f"method {name!r}: {agent_cls!r} is not an Agent subclass")
    if getattr(agent_cls, "style", None) != name:
        raise ConfigError(f"method {name!r}: {agent_cls.__name__}.style must be {name!r}")
    own: type[AgentConfig] = agent_cls.config_cls
    if not (isinstance(config_cls, type) and issubclass(config_cls, own)):
        raise ConfigError(f"method {name!r}: {config_cls!r} is not a {own.__name__}")
    return Method(agent_cls, config_cls)


def _as_method(name: str, source: object) -> Method:
    """A registration as a Method: an ``(agent class, config class)`` pair, either of them
    possibly a reference, or an agent class alone (with its own config class; the decorator
    form ``@METHODS.register(name)`` on the class)."""
    if isinstance(source, type):
        source = (source, getattr(source, "config_cls", None))
    if not (isinstance(source, tuple) and len(source) == 2):
        raise ConfigError(f"method {name!r}: register an (agent class, config class) pair, not {source!r}")
    agent_cls, config_cls = (import_reference(part) if isinstance(part, str) else part for part in source)
    return check_method(name, agent_cls, config_cls)


#: every method by name; ``METHODS[name]`` is its :class:`Method` (imported on first use)
METHODS: Registry[Method] = Registry("method", coerce=_as_method, error=ConfigError)

# -- the built-in methods: the one place they are named ------------------------------------------
METHODS.register("recap", ("recap.recap_agent:ReCAPAgent", "recap.config:ReCAPConfig"))
METHODS.register("react", ("recap.baselines:ReActAgent", "recap.baselines:ReActConfig"))
METHODS.register("act", ("recap.baselines:ActAgent", "recap.baselines:ActConfig"))
METHODS.register("cot", ("recap.baselines:CoTAgent", "recap.baselines:PlanConfig"))
METHODS.register("standard", ("recap.baselines:StandardAgent", "recap.baselines:PlanConfig"))
METHODS.register("adapt", ("recap.baselines:ADaPTAgent", "recap.baselines:ADaPTConfig"))
