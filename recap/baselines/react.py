"""ReAct (Yao et al., 2023): interleave a thought, one action and its observation, in one flat
context with a sliding window.

One episode:

* pinned: the demonstration (when there is one) and the task prompt (system text with the reply
  format, the environment rules, the first observation and the goal);
* each reply ``{"think", "action"}`` is looked up exactly among the valid actions. A valid
  action is executed and the next user message carries the new observation;
* an action that is not valid: in ``reject`` mode (Robotouille) it never reaches the
  environment and the next user message is error feedback naming it, followed by the unchanged
  observation (Robotouille's ReAct protocol); in ``step`` mode (ALFWorld) it is sent to the
  environment, whose answer ("Nothing happens.") is the next observation;
* it runs until the episode ends: success, the step cap, the call cap, JSON failures, a model
  error or a budget. ``invalid_streak`` optionally reproduces Robotouille's give-up rule;
* ``history``: ``window`` keeps the last K messages (Yao et al.'s ReAct, bounded by the shared
  window); ``last`` keeps only the last reply and the message after it (Robotouille's own ReAct,
  "last reasoning and action": the model sees the pins, its previous think + action and the
  current observation or error feedback).

The ``paper`` and ``released`` profiles use Robotouille's protocol on Robotouille (``history:
last``, give up after 3 rounds of 5 consecutive invalid actions) and Yao et al.'s on ALFWorld
(``history: window``, no give-up rule; invalid commands reach the game as in their setting).

Message kinds (also the call purposes): ``task`` (pinned), ``observation``, ``feedback`` (after
a rejected action), ``repair``. Hints for offline models: ``task`` (the goal), ``depth`` 0,
``valid_actions``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Any, ClassVar, Literal

from recap.agent import Agent
from recap.baselines import prompts as P
from recap.baselines.react_text import demo_texts, play_text
from recap.baselines.reply_format import check_reply_format, text_reply_defaults
from recap.config import AgentConfig, ConfigError
from recap.demo_script import DemoScript
from recap.env import InvalidActionError, Reset
from recap.jsonreply import action_reply
from recap.runtime import Episode, EpisodeEnd


@dataclass(frozen=True)
class ReActConfig(AgentConfig):
    """ReAct / Act settings.

    ``invalid_streak``: Robotouille's ReAct stops proposing after this many consecutive rejected
    actions (a "round"; it uses 5) and ends the episode after ``invalid_rounds`` such rounds (it
    uses 3). None (default) switches the rule off: the paper states no such rule, and the call
    cap bounds the episode anyway.
    """

    invalid_streak: int | None = None
    invalid_rounds: int = 3
    history: Literal["window", "last"] = "window"
    #: ``json`` (ours) or ``text``: the released code's plain-text replies and parsing
    #: (recap.baselines.react_text); ``text`` needs ``json_mode: false``
    reply_format: Literal["json", "text"] = "json"
    #: the text layout: ``labelled`` (Robotouille's "Reasoning:" / "Action:" lines) or ``yao``
    #: (ALFWorld's one line: "think: ..." or the command)
    text_layout: Literal["labelled", "yao"] = "labelled"

    @classmethod
    def profile_defaults(cls, profile: str, benchmark: str | None, ablation: str | None) -> dict[str, Any]:
        out = super().profile_defaults(profile, benchmark, ablation)
        if benchmark == "robotouille":
            # the benchmark's ReAct: last reasoning + action only; after 5 consecutive invalid
            # actions it starts a new round of feedback, and the third such round ends the episode
            out.update(history="last", invalid_streak=5, invalid_rounds=3)
        elif benchmark == "alfworld":
            out.update(history="window", invalid_streak=None)
        if profile == "released":
            out.update(text_reply_defaults(cls.released_text, benchmark))
        return out

    #: whether the released code's agent replies in plain text on ALFWorld (ReAct: react.py;
    #: Act's act.py asks for JSON)
    released_text: ClassVar[bool] = True

    def history_window(self) -> int:
        return 2 if self.history == "last" else self.window

    def history_counts_pins(self) -> bool:
        return False if self.history == "last" else self.window_counts_pins

    def validate(self) -> None:
        super().validate()
        if self.history not in ("window", "last"):
            raise ConfigError(f"history must be window or last, got {self.history!r}")
        if self.invalid_streak is not None and self.invalid_streak < 1:
            raise ConfigError(f"invalid_streak must be >= 1 or null, got {self.invalid_streak}")
        if self.invalid_rounds < 1:
            raise ConfigError(f"invalid_rounds must be >= 1, got {self.invalid_rounds}")
        check_reply_format(self)
        if self.text_layout not in ("labelled", "yao"):
            raise ConfigError(f"text_layout must be labelled or yao, got {self.text_layout!r}")


def flat_context(ep: Episode, goal: str) -> dict[str, Any]:
    """Hints for offline test models: flat agents work on the goal at depth 0."""
    valid = ep.driver.valid_actions
    return {"task": goal, "depth": 0, "valid_actions": list(valid) if valid is not None else None}


class ReActAgent(Agent):
    """ReAct: one call per step; each reply is a thought and the next action, and the next prompt is
    the new observation or the error feedback."""

    style = "react"
    config_cls = ReActConfig
    expected_format = P.action_format(True)
    #: Act is ReAct without the think field
    with_think: ClassVar[bool] = True
    reply_fields: ClassVar[tuple[str, ...]] = ("think", "action")
    #: one call per step
    estimate_calls_per_step = (1.0, 1.0)
    config: ReActConfig

    @classmethod
    def demo_replies(cls, script: DemoScript) -> list[dict[str, Any]]:
        """One reply per action, with the thought written before it (Act: the action alone)."""
        if cls.with_think:
            return [{"think": t, "action": a} for t, a in zip(script.step_thoughts, script.actions, strict=True)]
        return [{"action": a} for a in script.actions]

    def reply_format(self) -> str:
        return P.action_format(self.with_think)

    def shape_demo_replies(self, replies: list[Any]) -> list[Any]:
        if self.config.reply_format == "text":
            return demo_texts(self, replies)
        return super().shape_demo_replies(replies)

    def play(self, ep: Episode, reset: Reset) -> None:
        if self.config.reply_format == "text":
            return play_text(self, ep, reset)
        cfg, d = self.config, ep.driver
        ep.conv.pin(
            "task",
            P.action_task_prompt(
                rules=ep.env.rules(),
                observation=reset.observation,
                goal=reset.goal,
                with_think=self.with_think,
                preamble=not self.demo_mode,
            ),
        )
        parse = partial(action_reply, with_think=self.with_think)
        prompt: str | None = None  # the first call answers the pinned task prompt
        kind = "task"
        streak = rounds = 0
        while True:
            reply, _ = ep.conv.ask(prompt, kind, parse, context=flat_context(ep, reset.goal))
            action = reply["action"]
            try:
                d.execute(action)
            except InvalidActionError:
                prompt, kind = P.invalid_action_prompt(action, d.observation), "feedback"
                streak += 1
                if cfg.invalid_streak is not None and streak >= cfg.invalid_streak:
                    streak, rounds = 0, rounds + 1
                    if rounds >= cfg.invalid_rounds:
                        raise EpisodeEnd(
                            "agent_done",
                            f"{rounds} rounds of {cfg.invalid_streak} consecutive invalid actions",
                        ) from None
                continue
            streak = 0
            prompt, kind = P.observation_prompt(d.observation), "observation"
