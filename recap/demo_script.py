"""A one-shot demonstration written once, for no method in particular.

Why: every method shows the model the same solved example, each in its own reply format. If a
benchmark wrote the example's replies once per method, adding a method would mean editing every
benchmark. Instead a benchmark writes a :class:`DemoScript` — the example's actions with the
reasoning behind each one, the reasoning behind the whole plan, and the goal's decomposition —
and each agent class builds its own replies from it (:meth:`recap.agent.Agent.demo_replies`).

:class:`DemoReplies` is the ``Demonstration.replies`` mapping: replies written by hand for one
method's key win (a method whose replies cannot be derived, or a test's override); any other key
is answered by the registered agent class with that key (``Agent.style``), from the script.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

Replies = Sequence[Mapping[str, Any]]


@dataclass(frozen=True)
class DemoScript:
    """The solved example, method-neutral.

    * ``actions``: the environment actions in order; the last one reaches the goal;
    * ``step_thoughts``: the reasoning written just before each action (one per action);
    * ``plan_thought``: the reasoning behind the whole plan, written before the first action;
    * ``decomposition``: the goal broken into subtasks, as ``(think, subtasks)`` in the order a
      recursive decomposer asks for them: the root's list, a list for each child that is not
      itself an action, and a refined list for the parent after each child returns (the call
      order of :mod:`recap.recap_agent`). Its first entry is the root's decomposition.
    """

    actions: tuple[str, ...]
    step_thoughts: tuple[str, ...]
    plan_thought: str
    decomposition: tuple[tuple[str, tuple[str, ...]], ...]

    def __post_init__(self) -> None:
        if len(self.step_thoughts) != len(self.actions):
            raise ValueError(
                f"a demonstration script needs one thought per action ({len(self.step_thoughts)} thoughts, {len(self.actions)} actions)"
            )
        if not self.actions:
            raise ValueError("a demonstration script needs at least one action")


#: the agent classes that derive replies from a script, by method key, in registration order.
#: :mod:`recap.methods` fills it (the built-ins when it is imported, then ``register_method``), so
#: this module imports no agent: the agents import it.
_DERIVERS: dict[str, Any] = {}


def register_deriver(key: str, agent_cls: Any) -> None:
    """Let ``agent_cls`` (its ``demo_replies``) answer for ``key`` in every :class:`DemoReplies`."""
    _DERIVERS[key] = agent_cls


def unregister_deriver(key: str) -> None:
    """Undo :func:`register_deriver`."""
    _DERIVERS.pop(key, None)


def _agent_classes() -> list[Any]:
    """The registered agent classes, in registration order."""
    return list(_DERIVERS.values())


class DemoReplies(Mapping[str, Replies]):
    """Replies by method key: hand-written ones first, then those derived from the script by
    each registered agent class that can derive them."""

    explicit: dict[str, Replies]
    script: DemoScript | None

    def __init__(self, explicit: Mapping[str, Replies] | None = None, script: DemoScript | None = None) -> None:
        if isinstance(explicit, DemoReplies):  # re-wrapped: keep its overrides and its script
            script = script or explicit.script
            explicit = explicit.explicit
        self.explicit = dict(explicit or {})
        self.script = script

    def _derived(self, key: str) -> Replies | None:
        if self.script is None:
            return None
        for agent_cls in _agent_classes():
            if agent_cls.style == key:
                return agent_cls.demo_replies(self.script)
        return None

    def __getitem__(self, key: str) -> Replies:
        if key in self.explicit:
            return self.explicit[key]
        replies = self._derived(key)
        if replies is None:
            raise KeyError(key)
        return replies

    def __iter__(self) -> Iterator[str]:
        keys = list(self.explicit)
        if self.script is not None:
            for agent_cls in _agent_classes():
                if agent_cls.style not in keys and agent_cls.demo_replies(self.script) is not None:
                    keys.append(agent_cls.style)
        return iter(keys)

    def __len__(self) -> int:
        return sum(1 for _ in self)

    def __repr__(self) -> str:
        return f"DemoReplies({dict(self)!r})"
