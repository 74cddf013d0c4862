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
* ``history``: ``window`` keeps the last K messages (optionally keeping the first reply);
  ``last`` keeps only the last reply and the message after it (Robotouille's "last reasoning and
  action" ablation); ``all`` keeps everything (the released Act).

The ``paper`` and ``released`` profiles follow the authors' released baselines (see
``workers/envs/robotouille/protocol.py`` and ``workers/envs/alfworld/protocol.py`` for the file
and line of each item, each benchmark declaring its own): on Robotouille the
benchmark's "original" ReAct (the whole history trimmed past 64 messages, first exchange kept;
give up after 3 rounds of 5 consecutive invalid actions), Act with no window; on ALFWorld the
released react.py / act.py (valid actions in every observation, "OK." for a thought, explained
feedback after an invalid command, 128 messages counting the pins; Act with no window).

On an environment with tools (a coding benchmark) ReAct runs as mini-SWE-agent does, the paper's
ReAct baseline there (:mod:`recap.baselines.react_swe`).

``reply_format: text`` (the ``released`` profile's choice where the release reads plain text)
runs the same episode through :mod:`recap.baselines.react_text`: other reply parsing, the same
history, observations and explained feedback (:meth:`ReActAgent.explained_feedback`).

Message kinds (also the call purposes): ``task`` (pinned), ``observation``, ``feedback`` (after
a rejected or, explained, an invalid action), ``thought`` (after a thought), ``repair``. Hints
for offline models: ``task`` (the goal), ``depth`` 0, ``valid_actions``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

from recap.agent import Agent
from recap.baselines import prompts as P
from recap.baselines import text_prompts as T
from recap.baselines.act_json import MALFORMED_JSON, PARSE_ERROR_ACTION, read_reply
from recap.baselines.notebook_loop import notebook_release, play_react
from recap.baselines.react_swe import play_swe
from recap.baselines.react_text import demo_texts, play_text, raw_text
from recap.baselines.reply_format import RELEASED_TEXT, check_reply_format
from recap.config import AgentConfig, ConfigError
from recap.demo_script import DemoScript
from recap.env import Environment, InvalidActionError, Reset
from recap.jsonreply import action_reply
from recap.runtime import Episode, EpisodeEnd

#: how a ReAct action that only thinks starts (``think_actions``)
THOUGHT_PREFIX = "think:"


#: ``history: all`` keeps every message (no window): a bound no episode reaches
UNBOUNDED_WINDOW = 10**9


@dataclass(frozen=True)
class ReActConfig(AgentConfig):
    """ReAct / Act settings.

    ``invalid_streak``: Robotouille's ReAct stops proposing after this many consecutive rejected
    actions (a "round"; it uses 5) and ends the episode after ``invalid_rounds`` such rounds (it
    uses 3). None (default) switches the rule off: the paper states no such rule, and the call
    cap bounds the episode anyway.

    ``history``: ``window`` (the last K messages), ``last`` (the last reply and the message after
    it), ``all`` (no window: the released Act); ``window_keeps_first``: the first reply is never
    trimmed (the released Robotouille ReAct). ``think_actions``: an action written as a thought
    (``think: ...``; Act: a reply with a ``think`` field) is answered "OK." without reaching the
    environment or using a step. ``invalid_feedback``: after an action that reached the game but
    was not valid (``step`` mode), ``plain`` shows the game's answer alone, ``explained`` adds
    that it was not a valid action, three numbered likely causes and the valid actions.
    """

    invalid_streak: int | None = None
    invalid_rounds: int = 3
    history: Literal["window", "last", "all"] = "window"
    window_keeps_first: bool = False
    think_actions: bool = False
    invalid_feedback: Literal["plain", "explained"] = "plain"
    #: ``json`` (ours) or ``text``: the released code's plain-text replies and parsing
    #: (recap.baselines.react_text); ``text`` needs ``json_mode: false``
    reply_format: Literal["json", "text"] = "json"
    #: the text layout: ``labelled`` (Robotouille's "Reasoning:" / "Action:" lines) or ``yao``
    #: (ALFWorld's one line: "think: ..." or the command)
    text_layout: Literal["labelled", "yao"] = "labelled"
    #: JSON replies: ``repair`` (ours: a malformed reply is answered with a repair request) or
    #: ``game`` (the released ALFWorld Act: it becomes a command the game answers,
    #: recap.baselines.act_json)
    malformed_json: Literal["repair", "game"] = "repair"

    @classmethod
    def profile_defaults(cls, profile: str, ablation: str | None) -> dict[str, Any]:
        out = super().profile_defaults(profile, ablation)
        if profile == "released":
            # the released agents' plain-text replies (recap.baselines.reply_format); each
            # benchmark's protocol adds its own history, window and feedback (Robotouille's ReAct,
            # Yao et al.'s on ALFWorld: workers/envs/<benchmark>/protocol.py)
            out.update(RELEASED_TEXT)
        return out

    def history_window(self) -> int:
        if self.history == "last":
            return 2
        return UNBOUNDED_WINDOW if self.history == "all" else self.window

    def history_counts_pins(self) -> bool:
        return False if self.history != "window" else self.window_counts_pins

    def history_keep(self) -> int:
        return 1 if self.window_keeps_first and self.history != "last" else 0

    def validate(self) -> None:
        super().validate()
        if self.history not in ("window", "last", "all"):
            raise ConfigError(f"history must be window, last or all, got {self.history!r}")
        if self.invalid_streak is not None and self.invalid_streak < 1:
            raise ConfigError(f"invalid_streak must be >= 1 or null, got {self.invalid_streak}")
        if self.invalid_rounds < 1:
            raise ConfigError(f"invalid_rounds must be >= 1, got {self.invalid_rounds}")
        if self.invalid_feedback not in ("plain", "explained"):
            raise ConfigError(f"invalid_feedback must be plain or explained, got {self.invalid_feedback!r}")
        if self.window_keeps_first and self.history == "window" and self.window < 4:
            raise ConfigError("window must be >= 4 messages when it keeps the first reply")
        check_reply_format(self)
        if self.malformed_json not in ("repair", "game"):
            raise ConfigError(f"malformed_json must be repair or game, got {self.malformed_json!r}")
        if self.text_layout not in ("labelled", "yao"):
            raise ConfigError(f"text_layout must be labelled or yao, got {self.text_layout!r}")


def _keep(obj: dict[str, Any]) -> dict[str, Any]:
    return obj


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

    def parse_reply(self, obj: dict[str, Any]) -> dict[str, Any]:
        """The reply's fields. With ``think_actions``, Act also takes a reply that holds a
        ``think`` and no action (a thought) and keeps the think of one that holds both."""
        if self.config.think_actions and not self.with_think:
            think = obj.get("think")
            if isinstance(think, str) and "action" not in obj:
                return {"think": think, "action": None}
            reply = action_reply(obj, with_think=False)
            if isinstance(think, str):
                reply["think"] = think
            return reply
        return action_reply(obj, with_think=self.with_think)

    def is_thought(self, reply: dict[str, Any]) -> bool:
        """A reply that only thinks (``think_actions``): ReAct's action ``think: ...``
        (alfworld-recap/react_alfworld/react.py:159), Act's reply without an action."""
        action = reply["action"]
        if action is None:
            return True
        return self.with_think and action.lower().startswith(THOUGHT_PREFIX)

    def explained_feedback(self, ep: Episode, action: str) -> str:
        """The message after a command that reached the game but was not valid
        (``invalid_feedback: explained``), for the JSON and the text loop alike: the valid
        actions are listed unless the game's answer already lists them."""
        d = ep.driver
        listed = ep.env.lists_valid_actions
        return P.explained_invalid_prompt(action, d.observation, None if listed else d.valid_actions, with_think=self.with_think)

    def shape_demo_replies(self, replies: list[Any]) -> list[Any]:
        if self.config.reply_format == "text":
            return demo_texts(self, replies)
        return super().shape_demo_replies(replies)

    def episode_config(self, env: Environment) -> AgentConfig:
        """The derived settings, and on an environment with tools (mini-SWE-agent's loop) no JSON
        mode: its replies are plain text."""
        cfg = super().episode_config(env)
        if self.with_think and env.tool_defs() and cfg.json_mode:
            cfg = dataclasses.replace(cfg, json_mode=False)
        return cfg

    def play(self, ep: Episode, reset: Reset) -> None:
        notebook = notebook_release(ep)
        if notebook is not None:  # prompts: release on FEVER: the notebook's own loop
            return play_react(ep, reset, notebook, self.with_think)
        if self.with_think and ep.env.tool_defs():  # a coding environment: mini-SWE-agent's loop
            return play_swe(ep, reset, self.config.max_json_repairs)
        if self.config.reply_format == "text":
            return play_text(self, ep, reset)
        cfg, d = self.config, ep.driver
        released = self._pin_task(ep, reset)
        prompt: str | None = None  # the first call answers the pinned task prompt
        kind = "task"
        streak = rounds = 0
        while True:
            reply, prompt, kind = self._next_reply(ep, reset, prompt, kind)
            if reply is None:
                continue
            if cfg.think_actions and self.is_thought(reply):
                # a thought: no environment step, no step used (react.py:159-160, act.py:218-219)
                prompt, kind = P.THOUGHT_ACK, "thought"
                continue
            action = reply["action"]
            valid = d.is_valid(action)
            try:
                d.execute(action)
            except InvalidActionError:
                prompt, kind = P.invalid_action_prompt(action, d.observation), "feedback"
                streak, rounds = self._count_invalid(streak, rounds)
                continue
            streak = 0
            prompt, kind = self._after_step(ep, reply, action, valid, released)

    def _pin_task(self, ep: Episode, reset: Reset) -> bool:
        """Pin the task prompt; True under ``prompts: release`` on ALFWorld (the released wording)."""
        cfg = self.config
        # prompts: release on ALFWorld (Act: the JSON loop): the released first prompt with its
        # JSON request (act_alfworld/act.py:158-172, 304), and each observation as the release
        # sends it, without our heading (act.py:211)
        released = getattr(ep.extra.get("release"), "first_turn", None) == "framed"
        if released:
            goal = "" if reset.goal in reset.observation else f"\n\nGoal: {reset.goal}"
            ep.conv.pin("task", T.release_alfworld_task(f"{reset.observation}{goal}", json_example=T.RELEASE_JSON_EXAMPLE))
        else:
            ep.conv.pin(
                "task",
                P.action_task_prompt(
                    rules=ep.env.rules(),
                    observation=reset.observation,
                    goal=reset.goal,
                    with_think=self.with_think,
                    preamble=not self.demo_mode,
                    think_actions=cfg.think_actions,
                ),
            )
        return released

    def _next_reply(
        self, ep: Episode, reset: Reset, prompt: str | None, kind: str
    ) -> tuple[dict[str, Any] | None, str | None, str]:
        """(reply, prompt, kind): the model's next reply to ``prompt``; with ``malformed_json: game``
        a reply the release would not act on gives None and the next prompt to send instead."""
        if self.config.malformed_json != "game":
            reply, _ = ep.conv.ask(prompt, kind, self.parse_reply, context=flat_context(ep, reset.goal))
            return reply, prompt, kind
        raw, _ = ep.conv.ask(prompt, kind, _keep, context=flat_context(ep, reset.goal), decode=raw_text)
        read = read_reply(raw["text"])
        if read.malformed:
            # the release sends its placeholder command to the game (a step) and shows
            # its own note instead of the game's answer (act_alfworld/act.py:183-199)
            try:
                ep.driver.execute(read.action or PARSE_ERROR_ACTION)
            except InvalidActionError:
                pass  # an environment that rejects invalid commands takes no step
            return None, MALFORMED_JSON, "feedback"
        if read.action is None and read.think is None:
            # neither field: the release sends its last message again (act.py:221)
            return None, prompt if prompt is not None else reset.observation, kind
        if read.action is None:  # a thought, whatever think_actions says (act.py:218-219)
            return None, P.THOUGHT_ACK, "thought"
        return read.as_reply(), prompt, kind

    def _count_invalid(self, streak: int, rounds: int) -> tuple[int, int]:
        """(streak, rounds) after one more rejected action; ends the episode after ``invalid_rounds``
        rounds of ``invalid_streak`` in a row (Robotouille's give-up rule)."""
        cfg = self.config
        streak += 1
        if cfg.invalid_streak is not None and streak >= cfg.invalid_streak:
            streak, rounds = 0, rounds + 1
            if rounds >= cfg.invalid_rounds:
                raise EpisodeEnd(
                    "agent_done",
                    f"{rounds} rounds of {cfg.invalid_streak} consecutive invalid actions",
                ) from None
        return streak, rounds

    def _after_step(self, ep: Episode, reply: dict[str, Any], action: str, valid: bool, released: bool) -> tuple[str, str]:
        """(prompt, kind) after an executed action: "OK." for the released Act's thought, explained
        feedback for an invalid one, else the observation."""
        cfg, d = self.config, ep.driver
        if cfg.think_actions and reply.get("think") is not None and not self.with_think:
            # the released Act answers "OK." to any reply with a think, even one that also
            # acted: the action runs, its observation is not shown (act_alfworld/act.py:218-219)
            return P.THOUGHT_ACK, "thought"
        if not valid and cfg.invalid_feedback == "explained":
            return self.explained_feedback(ep, action), "feedback"
        return (d.observation if released else P.observation_prompt(d.observation)), "observation"
