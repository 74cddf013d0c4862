"""A one-shot demonstration written once, for no method in particular.

Why: every method shows the model the same solved example, each in its own reply format. If a
benchmark wrote the example's replies once per method, adding a method would mean editing every
benchmark. Instead a benchmark writes a :class:`DemoScript` — the example's actions with the
reasoning behind each one, the reasoning behind the whole plan, and the goal's decomposition —
and each agent class builds its own replies from it (:meth:`recap.agent.Agent.demo_replies`;
:class:`recap.demo_replies.DemoReplies` asks every registered method).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
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
