"""The base of every agent: one episode = reset, pin the demonstration and the task prompt,
play until an :class:`EpisodeEnd`, return an :class:`EpisodeResult`.

Demonstrations are rendered by running the agent itself, with the same settings, on the
demonstration's environment against a scripted model that returns the demonstration's replies.
The transcript is therefore in exactly the agent's own prompt format for every ablation, and it
is flattened into one pinned user message. ``demo_observations`` decides which of the
example's observations the transcript shows (:class:`ElidedObservations`).

The call cap: unless a run fixes ``max_llm_calls``, each episode's cap is derived from its step
cap S by the method's own formula ``ceil(calls_per_step x S) + call_overhead +
max_json_repairs``, so a method that needs more calls per environment step (ReCAP: a descend
and a return per action) is never cut by calls before it could use its step budget.
"""

from __future__ import annotations

import dataclasses
import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Any, ClassVar

from recap.config import OMITTED_OBSERVATION, AgentConfig
from recap.demo_script import DemoScript
from recap.env import Demonstration, Environment, Reset, Step
from recap.llm import LLMClient
from recap.release_prompt import ReleasePrompt
from recap.runtime import Conversation, Emit, EnvDriver, Episode, EpisodeEnd, EpisodeResult
from recap.scripted import ScriptedClient
from schemas.records import MessageRecord

_DEMO_CACHE: dict[tuple[str, str, str], str] = {}


class DemonstrationError(RuntimeError):
    """A demonstration's replies do not solve its environment with this agent."""


def _discard(_record: Any) -> None:
    return None


class ElidedObservations(Environment):
    """A demonstration environment whose observations are left out of the transcript.

    Everything the agent acts on (valid actions, success, the step cap) comes from the wrapped
    environment unchanged; only the observation *text* is replaced by
    :data:`~recap.config.OMITTED_OBSERVATION` — after the first one (``keep_first``) or always.
    """

    def __init__(self, inner: Environment, *, keep_first: bool) -> None:
        self.inner = inner
        self.keep_first = keep_first
        for name in (
            "instance_id",
            "benchmark",
            "split",
            "task",
            "layout_seed",
            "invalid_action_mode",
            "optimal_steps",
            "max_steps",
            "test_double",
            "partially_observed",
        ):
            setattr(self, name, getattr(inner, name))

    def reset(self) -> Reset:
        r = self.inner.reset()
        return r if self.keep_first else dataclasses.replace(r, observation=OMITTED_OBSERVATION)

    def step(self, action: str) -> Step:
        return dataclasses.replace(self.inner.step(action), observation=OMITTED_OBSERVATION)

    def rules(self) -> str:
        return self.inner.rules()

    def demonstration(self) -> Demonstration | None:
        return None

    def failure_hints(self) -> str:
        return self.inner.failure_hints()

    @property
    def steps_taken(self) -> int:
        return self.inner.steps_taken

    def close(self) -> None:
        self.inner.close()


class Agent(ABC):
    """A method. Everything that differs between methods is declared here, by the class:

    * ``style``: the method's key (its name in ``recap.methods.METHODS``, its key for
      hand-written demonstration replies, the ``style`` hint);
    * ``expected_format`` / :meth:`reply_format`: the reply shape shown in repair messages, and
      ``reply_fields``: the same shape as field names, sent to offline test-double models in
      ``hints["reply_fields"]`` so they can answer any method without knowing its name;
    * :meth:`demo_replies`: the method's demonstration replies, built from a benchmark's
      method-neutral :class:`~recap.demo_script.DemoScript`;
    * ``calls_per_step`` / ``call_overhead``: the derived call cap; ``one_shot`` and
      ``estimate_calls_per_step``: what ``recap estimate`` assumes before a run.
    """

    #: key into Demonstration.replies and the ``style`` hint for offline models
    style: ClassVar[str]
    config_cls: ClassVar[type[AgentConfig]] = AgentConfig
    #: the reply shape, as shown to the model in repair messages
    expected_format: ClassVar[str]
    #: the reply's fields, in order (``think``, ``subtasks``, ``action``, ``actions``), as the
    #: offline test doubles fill them
    reply_fields: ClassVar[tuple[str, ...]] = ("think", "subtasks")
    #: the derived call cap: ceil(calls_per_step x step cap) + call_overhead + max_json_repairs
    calls_per_step: ClassVar[float] = 2.0
    call_overhead: ClassVar[int] = 10
    #: one call answers the whole episode (the estimate counts one call plus repairs)
    one_shot: ClassVar[bool] = False
    #: (low, high) calls per allowed environment step that ``recap estimate`` assumes
    estimate_calls_per_step: ClassVar[tuple[float, float]] = (1.0, 2.5)

    def __init__(self, config: AgentConfig | None = None) -> None:
        self.config = config if config is not None else self.config_cls()
        if not isinstance(self.config, self.config_cls):
            raise TypeError(f"{type(self).__name__} needs a {self.config_cls.__name__}")
        self.config.validate()
        #: True while rendering a demonstration (prompts leave out the system text and rules)
        self.demo_mode = False

    @property
    def name(self) -> str:
        return self.style

    # -- one episode -------------------------------------------------------------------------
    def run(
        self,
        env: Environment,
        client: LLMClient,
        *,
        episode_id: str = "episode",
        emit: Emit | None = None,
        demonstration: str | None | bool | ReleasePrompt = True,
    ) -> EpisodeResult:
        """Play one episode. ``demonstration``: True renders the env's demo, False/None uses
        none, a string is used as the demonstration text as is, a :class:`ReleasePrompt` pins
        the authors' messages with their roles (``ep.extra["release"]`` tells ``play`` to leave
        out our system text and rules)."""
        emit = emit or _discard
        conv = Conversation(
            episode_id=episode_id,
            client=client,
            config=self.episode_config(env),
            style=self.style,
            emit=emit,
            expected_format=self.reply_format(),
            reply_fields=self.reply_fields,
        )
        ep = Episode(conv=conv, driver=EnvDriver(env, episode_id, emit), env=env, emit=emit)
        try:
            if isinstance(demonstration, ReleasePrompt):
                ep.extra["release"] = demonstration
                pins = [(role, "release", text) for role, text in demonstration.messages]
            else:
                demo_text = self.demonstration_text(env) if demonstration is True else (demonstration or None)
                pins = [("user", "demonstration", demo_text)] if demo_text else []
            reset = ep.driver.reset()
            for role, kind, text in pins:
                conv.pin_message(role, kind, text)
            self.play(ep, reset)
            raise EpisodeEnd("agent_done")
        except EpisodeEnd as end:
            # a limit reached: the work so far is handed in and graded where the environment
            # has any (SWE-agent's autosubmission), under every profile
            result = ep.result(ep.driver.submit_at_limit(end), self.max_depth(ep))
        finally:
            self.finish(ep)
        return result

    def call_cap(self, max_steps: int) -> int:
        """The method's call cap for an episode whose step cap is ``max_steps``."""
        return math.ceil(self.calls_per_step * max_steps) + self.call_overhead + self.config.max_json_repairs

    def episode_config(self, env: Environment) -> AgentConfig:
        """The settings one episode runs with: a derived call cap filled in from ``env``."""
        if self.config.max_llm_calls is not None:
            return self.config
        return dataclasses.replace(self.config, max_llm_calls=self.call_cap(int(env.max_steps)))

    @abstractmethod
    def play(self, ep: Episode, reset: Reset) -> None:
        """Run the method until it raises EpisodeEnd (returning means the agent is done)."""

    def reply_format(self) -> str:
        return self.expected_format

    def refuses_env(self, env: Environment) -> str | None:
        """Why this method cannot play ``env`` at all (one line), or None. Preflight asks before
        anything runs (a coding agent on a benchmark whose actions are not tool calls). Default:
        every environment."""
        return None

    def max_depth(self, ep: Episode) -> int:
        return 0

    def finish(self, ep: Episode) -> None:
        """Emit whatever the agent keeps until the end (the ReCAP tree)."""

    # -- demonstrations ----------------------------------------------------------------------
    @classmethod
    def demo_replies(cls, script: DemoScript) -> list[dict[str, Any]] | None:
        """This method's model replies, in call order, that solve the demonstration ``script``
        describes; None when the method cannot derive them (it then needs replies written for
        its key in the Demonstration, or renders its demonstration another way)."""
        return None

    def shape_demo_reply(self, reply: Any) -> Any:
        """A demonstration reply in this configuration's reply format (ablations drop fields)."""
        return reply

    def shape_demo_replies(self, replies: list[Any]) -> list[Any]:
        """The demonstration's replies in call order, each through :meth:`shape_demo_reply`; a
        method whose reply format splits one reply into several calls (plain-text ReAct on
        ALFWorld: the thought, then the command) overrides this."""
        return [self.shape_demo_reply(r) for r in replies]

    def demo_config(self) -> AgentConfig:
        """Settings for rendering a demonstration: nothing trimmed, no caps that could cut it."""
        return dataclasses.replace(
            self.config, window=100_000, max_llm_calls=100_000, max_episode_tokens=None, max_episode_cost_usd=None
        )

    def demonstration_text(self, env: Environment) -> str | None:
        demo = env.demonstration()
        if demo is None:
            return None
        return self.render_demonstration(demo)

    def render_demonstration(self, demo: Demonstration) -> str:
        key = (type(self).__name__, demo.name, self.config.to_json())
        if key in _DEMO_CACHE:
            return _DEMO_CACHE[key]
        replies = demo.replies.get(self.style)
        if replies is None and demo.script is not None:  # this class derives its own, registered or not
            replies = type(self).demo_replies(demo.script)
        if replies is None:
            raise DemonstrationError(f"demonstration {demo.name!r} has no replies for style {self.style!r}")
        messages, result = self.scripted_demo_run(demo, self.shape_demo_replies(list(replies)), f"demo:{demo.name}")
        if not result.success:
            raise DemonstrationError(
                f"demonstration {demo.name!r} does not reach the goal with {type(self).__name__} ({result.end_reason}: {result.error})"
            )
        text = format_transcript(messages)
        _DEMO_CACHE[key] = text
        return text

    def scripted_demo_run(
        self, demo: Demonstration, replies: list[Any], episode_id: str, prepare: Callable[[Agent], None] | None = None
    ) -> tuple[list[MessageRecord], EpisodeResult]:
        """Play ``demo`` with a demo-mode copy of this agent answering from ``replies``; the
        messages it exchanged (the demonstration's text) and the result. ``prepare`` adjusts the
        copy first (ADaPT picks which of its parts plays)."""
        agent = type(self)(self.demo_config())
        agent.demo_mode = True
        if prepare is not None:
            prepare(agent)
        messages: list[MessageRecord] = []

        def keep(record: Any) -> None:
            if isinstance(record, MessageRecord):
                messages.append(record)

        result = agent.run(
            self.demo_env(demo),
            ScriptedClient(replies, model="demonstration"),
            episode_id=episode_id,
            emit=keep,
            demonstration=False,
        )
        return messages, result

    def demo_env(self, demo: Demonstration) -> Environment:
        """The demonstration's environment, with observations left out as configured."""
        env = demo.make_env()
        if self.config.demo_observations == "all":
            return env
        return ElidedObservations(env, keep_first=self.config.demo_observations == "first")


def format_transcript(messages: list[MessageRecord]) -> str:
    """The demonstration run's messages as the text pinned in prompts: each labelled as an example
    prompt or reply, framed as one complete example that reaches the goal."""
    parts = ["Here is a complete example of the interaction, from the first prompt to the goal being reached."]
    for m in messages:
        label = "Example prompt" if m.role == "user" else "Example reply"
        parts.append(f"[{label}]\n{m.content}")
    parts.append("[End of example: the goal was reached.]")
    return "\n\n".join(parts)
