"""The one-shot ALFWorld demonstration of each task type as the agents get it: script, replies, replay.

The paper uses one training game per task type; ALFWorld's training games are not in our data,
so each demonstration is an invented household episode
(:mod:`workers.envs.alfworld.demo_episodes`) solved with commands in 2.1.1 wording. For every task type we write the episode once, as a method-neutral
:class:`~recap.demo_script.DemoScript`; each agent class derives its replies from it:

- ``steps``: each action with the thought that leads to it (ReAct's replies; Act's are the
  actions alone);
- the plan's thought (:func:`plan_think`) walks through the same reasoning in order (CoT's one
  reply, with every action; Standard's without the think). The paper does not run CoT and
  Standard on ALFWorld - an open-loop plan cannot look inside closed receptacles - but a sweep
  may, and then they are shown the same episode as every other method;
- ``recap``: ReCAP's decomposition replies in its call order (written with the episodes,
  :mod:`workers.envs.alfworld.demo_episodes`).

For game-file version 2.1.2 the same episodes are recorded in 2.1.2 wording and the command
strings in the replies are rewritten (``put X in/on Y`` -> ``move X to Y``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from recap.demo_replies import DemoReplies
from recap.demo_script import DemoScript
from recap.env import Demonstration
from workers.envs.alfworld.demo_episodes import DEMOS, WrittenDemo
from workers.envs.alfworld.household import record
from workers.envs.alfworld.replay import Recording, ReplayEnvironment
from workers.envs.alfworld.rules import failure_hints_text, rules_text
from workers.envs.alfworld.task_types import TASK_TYPES
from workers.envs.alfworld.wording import to_version

#: the methods whose replies the scripts yield today (the paper runs ReCAP, ReAct and Act here;
#: ADaPT's executor uses the ReAct replies). Derived by the agent classes, not listed anywhere else.
STYLES = ("recap", "react", "act", "cot", "standard")


def recording_for(short_type: str, version: str = "2.1.1") -> Recording:
    """The recorded episode of the demonstration for ``short_type`` in ``version`` wording."""
    demo = _demo(short_type)
    return record(
        demo.scene,
        [to_version(a, version) for a, _ in demo.steps],
        name=f"demo-{short_type}",
        split=short_type,
        task=TASK_TYPES[short_type],
        version=version,
    )


def script_for(short_type: str, version: str = "2.1.1") -> DemoScript:
    """The demonstration for ``short_type`` written once, commands in ``version`` wording."""
    demo = _demo(short_type)
    return DemoScript(
        actions=tuple(to_version(a, version) for a, _ in demo.steps),
        step_thoughts=tuple(t for _, t in demo.steps),
        plan_thought=plan_think(demo),
        decomposition=tuple((think, tuple(to_version(s, version) for s in subtasks)) for think, subtasks in demo.recap),
    )


def replies_for(short_type: str, version: str = "2.1.1") -> dict[str, list[dict[str, Any]]]:
    """The model replies per method key, as the registered agent classes derive them from the
    script (commands in ``version`` wording)."""
    return {k: [dict(r) for r in v] for k, v in DemoReplies(script=script_for(short_type, version)).items()}


def plan_think(demo: WrittenDemo) -> str:
    """CoT's single think: the episode's reasoning, step by step, written before acting."""
    steps = " ".join(f"({i}) {thought}" for i, (_, thought) in enumerate(demo.steps, 1))
    return f"I write the whole plan now, one step per action, reasoning about where things are likely to be: {steps}"


def demonstration_name(short_type: str, version: str = "2.1.1", show_valid_actions: bool = False) -> str:
    """``alfworld-<type>``, plus ``-2.1.2`` and ``-valid-actions`` for those variants.

    Agents cache a rendered demonstration by its name, so every variant that renders to a
    different text needs its own name.
    """
    name = f"alfworld-{short_type}"
    if version != "2.1.1":
        name += f"-{version}"
    if show_valid_actions:
        name += "-valid-actions"
    return name


def demonstration_for(
    short_type: str, version: str = "2.1.1", max_steps: int = 50, *, show_valid_actions: bool = False
) -> Demonstration:
    """The demonstration for ``short_type``; ``show_valid_actions`` as in the episode's game
    environment (the replay then appends the valid actions to every observation)."""
    recording = recording_for(short_type, version)
    rules, hints = rules_text(version, max_steps), failure_hints_text()

    def make_env() -> ReplayEnvironment:
        return ReplayEnvironment(
            recording, rules=rules, failure_hints=hints, max_steps=max_steps, show_valid_actions=show_valid_actions
        )

    return Demonstration(
        name=demonstration_name(short_type, version, show_valid_actions),
        make_env=make_env,
        script=script_for(short_type, version),
    )


def _demo(short_type: str) -> WrittenDemo:
    try:
        return DEMOS[short_type]
    except KeyError:
        raise ValueError(f"no ALFWorld demonstration for {short_type!r}; task types: {', '.join(DEMOS)}") from None


def demo_task_types() -> Sequence[str]:
    """The short task types that have a written demonstration (one per ALFWorld task type), in the
    order they are written."""
    return tuple(DEMOS)
