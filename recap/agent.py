"""The base of every agent: one episode = reset, pin the demonstration and the task prompt,
play until an :class:`EpisodeEnd`, return an :class:`EpisodeResult`.

Demonstrations are rendered by running the agent itself, with the same settings, on the
demonstration's environment against a scripted model that returns the demonstration's replies.
The transcript is therefore in exactly the agent's own prompt format for every ablation, and it
is flattened into one pinned user message.
"""

from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod
from typing import Any, ClassVar

from recap.config import AgentConfig
from recap.env import Demonstration, Environment, Reset
from recap.llm import LLMClient
from recap.runtime import Conversation, EnvDriver, Emit, Episode, EpisodeEnd, EpisodeResult
from recap.scripted import ScriptedClient
from schemas.records import MessageRecord

_DEMO_CACHE: dict[tuple[str, str, str], str] = {}


class DemonstrationError(RuntimeError):
    """A demonstration's replies do not solve its environment with this agent."""


def _discard(_record: Any) -> None:
    return None


class Agent(ABC):
    #: key into Demonstration.replies and the ``style`` hint for offline models
    style: ClassVar[str]
    config_cls: ClassVar[type[AgentConfig]] = AgentConfig
    #: the reply shape, as shown to the model in repair messages
    expected_format: ClassVar[str]

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
        demonstration: str | None | bool = True,
    ) -> EpisodeResult:
        """Play one episode. ``demonstration``: True renders the env's demo, False/None uses
        none, a string is used as the demonstration text as is."""
        emit = emit or _discard
        conv = Conversation(
            episode_id=episode_id,
            client=client,
            config=self.config,
            style=self.style,
            emit=emit,
            expected_format=self.reply_format(),
        )
        ep = Episode(conv=conv, driver=EnvDriver(env, episode_id, emit), env=env, emit=emit)
        try:
            demo_text = self.demonstration_text(env) if demonstration is True else (demonstration or None)
            reset = ep.driver.reset()
            if demo_text:
                conv.pin("demonstration", demo_text)
            self.play(ep, reset)
            raise EpisodeEnd("agent_done")
        except EpisodeEnd as end:
            result = ep.result(end, self.max_depth(ep))
        finally:
            self.finish(ep)
        return result

    @abstractmethod
    def play(self, ep: Episode, reset: Reset) -> None:
        """Run the method until it raises EpisodeEnd (returning means the agent is done)."""

    def reply_format(self) -> str:
        return self.expected_format

    def max_depth(self, ep: Episode) -> int:
        return 0

    def finish(self, ep: Episode) -> None:
        """Emit whatever the agent keeps until the end (the ReCAP tree)."""

    # -- demonstrations ----------------------------------------------------------------------
    def shape_demo_reply(self, reply: Any) -> Any:
        """A demonstration reply in this configuration's reply format (ablations drop fields)."""
        return reply

    def demo_config(self) -> AgentConfig:
        """Settings for rendering a demonstration: nothing trimmed, no caps that could cut it."""
        return dataclasses.replace(self.config, window=100_000, max_llm_calls=100_000, max_episode_tokens=None, max_episode_cost_usd=None)

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
        if replies is None:
            raise DemonstrationError(f"demonstration {demo.name!r} has no replies for style {self.style!r}")
        agent = type(self)(self.demo_config())
        agent.demo_mode = True
        messages: list[MessageRecord] = []

        def keep(record: Any) -> None:
            if isinstance(record, MessageRecord):
                messages.append(record)

        shaped = [self.shape_demo_reply(r) for r in replies]
        result = agent.run(demo.make_env(), ScriptedClient(shaped, model="demonstration"), episode_id=f"demo:{demo.name}", emit=keep, demonstration=False)
        if not result.success:
            raise DemonstrationError(f"demonstration {demo.name!r} does not reach the goal with {type(self).__name__} ({result.end_reason}: {result.error})")
        text = format_transcript(messages)
        _DEMO_CACHE[key] = text
        return text


def format_transcript(messages: list[MessageRecord]) -> str:
    parts = ["Here is a complete example of the interaction, from the first prompt to the goal being reached."]
    for m in messages:
        label = "Example prompt" if m.role == "user" else "Example reply"
        parts.append(f"[{label}]\n{m.content}")
    parts.append("[End of example: the goal was reached.]")
    return "\n\n".join(parts)
