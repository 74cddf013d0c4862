"""CoT (chain-of-thought): one call returns the reasoning and the whole plan
``{"think", "actions": [...]}``, which is then executed open-loop.

This is how Robotouille's I/O-CoT agent is used: it sees the initial state, the goal and the
valid actions once, writes the complete action sequence (reasoning about the state each action
leads to), and is never asked again. Policy decisions (documented, configurable):

* each planned action is looked up exactly among the *current* valid actions and executed;
* an action that is not valid — ``reject`` mode: ``on_invalid="stop"`` (default) records the
  rejected attempt and ends the episode with ``agent_done``: an open-loop plan has no way to
  recover, and Robotouille's I/O agent also terminates on an invalid plan. ``on_invalid="skip"``
  records it and goes on with the next planned action. ``step`` mode: the action is sent to the
  environment like any other (the game answers "Nothing happens.") and the plan goes on;
* the plan running out before the goal is reached ends the episode with ``agent_done``;
  the step cap applies as for every agent (a plan longer than the cap ends with ``step_cap``).

Messages: the pinned ``task`` prompt and the reply (plus ``repair`` messages); no observation
is ever sent back, since the model is not asked again.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Any, ClassVar, Literal

from recap.agent import Agent
from recap.baselines import prompts as P
from recap.baselines.notebook_loop import notebook_release, play_one_call
from recap.baselines.plan_text import demo_texts, play_text
from recap.baselines.react import flat_context
from recap.baselines.reply_format import RELEASED_TEXT, check_reply_format
from recap.config import AgentConfig, ConfigError
from recap.demo_script import DemoScript
from recap.env import InvalidActionError, Reset
from recap.jsonreply import plan_reply
from recap.runtime import Episode, EpisodeEnd


@dataclass(frozen=True)
class PlanConfig(AgentConfig):
    """CoT / Standard settings: what an invalid planned action does in ``reject`` mode."""

    on_invalid: Literal["stop", "skip"] = "stop"
    #: ``json`` (ours) or ``text``: the released I/O agents' plain-text plan, checked whole
    #: first (recap.baselines.plan_text); ``text`` needs ``json_mode: false``
    reply_format: Literal["json", "text"] = "json"
    #: the whole plan in one reply: the longest expert plan (async 9 @420, 103 actions) is
    #: 1,286 tokens with a think (bench/protocol.py); 1024 cut it
    max_tokens: int | None = 3072

    def validate(self) -> None:
        super().validate()
        if self.on_invalid not in ("stop", "skip"):
            raise ConfigError(f"on_invalid must be 'stop' or 'skip', got {self.on_invalid!r}")
        check_reply_format(self)

    @classmethod
    def profile_defaults(cls, profile: str, ablation: str | None) -> dict[str, Any]:
        out = super().profile_defaults(profile, ablation)
        if profile == "released":
            # the released I/O agents' plain-text plan (Robotouille's; ALFWorld's protocol keeps
            # our JSON plan, the release having no I/O agent there)
            out.update(RELEASED_TEXT)
        return out


class CoTAgent(Agent):
    """CoT: one call returns the reasoning and the whole plan, which then runs open-loop without
    asking the model again (see the module docstring for invalid planned actions)."""

    style = "cot"
    config_cls = PlanConfig
    expected_format = P.plan_format(True)
    #: Standard is CoT without the think field
    with_think: ClassVar[bool] = True
    #: one call (plus JSON repairs), whatever the step cap
    calls_per_step = 0.0
    call_overhead = 1
    one_shot = True
    reply_fields: ClassVar[tuple[str, ...]] = ("think", "actions")
    config: PlanConfig

    @classmethod
    def demo_replies(cls, script: DemoScript) -> list[dict[str, Any]]:
        """The whole plan in one reply, after the plan's reasoning (Standard: the plan alone)."""
        if cls.with_think:
            return [{"think": script.plan_thought, "actions": list(script.actions)}]
        return [{"actions": list(script.actions)}]

    def reply_format(self) -> str:
        return P.plan_format(self.with_think)

    def shape_demo_replies(self, replies: list[Any]) -> list[Any]:
        if self.config.reply_format == "text":
            return demo_texts(self, replies)
        return super().shape_demo_replies(replies)

    def play(self, ep: Episode, reset: Reset) -> None:
        notebook = notebook_release(ep)
        if notebook is not None:  # prompts: release on FEVER: the notebook's one call
            return play_one_call(ep, reset, notebook, self.with_think)
        if self.config.reply_format == "text":
            return play_text(self, ep, reset)
        ep.conv.pin(
            "task",
            P.plan_task_prompt(
                rules=ep.env.rules(),
                observation=reset.observation,
                goal=reset.goal,
                with_think=self.with_think,
                preamble=not self.demo_mode,
            ),
        )
        parse = partial(plan_reply, with_think=self.with_think)
        reply, _ = ep.conv.ask(None, "task", parse, context=flat_context(ep, reset.goal))
        actions = reply["actions"]
        for i, action in enumerate(actions, 1):
            try:
                ep.driver.execute(action)
            except InvalidActionError:
                if self.config.on_invalid == "stop":
                    raise EpisodeEnd(
                        "agent_done",
                        f"planned action {i} of {len(actions)} ({action!r}) is not a valid action; the plan stops",
                    ) from None
        raise EpisodeEnd("agent_done", f"the plan's {len(actions)} action(s) ran out before the goal was reached")
