"""Helpers for the ReCAP tests: run an episode on a scripted model and split the records."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from recap.blocksworld import BlocksworldEnv
from recap.config import ReCAPConfig
from recap.recap_agent import ReCAPAgent
from recap.runtime import EpisodeResult
from recap.scripted import ScriptedClient
from schemas.records import CallRecord, MessageRecord, NodeRecord, StepRecord


@dataclass
class Run:
    result: EpisodeResult
    client: ScriptedClient
    messages: list[MessageRecord] = field(default_factory=list)
    calls: list[CallRecord] = field(default_factory=list)
    nodes: list[NodeRecord] = field(default_factory=list)
    steps: list[StepRecord] = field(default_factory=list)

    def kinds(self) -> list[str]:
        return [m.kind for m in self.messages]

    def user(self, kind: str) -> list[str]:
        return [m.content for m in self.messages if m.kind == kind]


def demo_env() -> BlocksworldEnv:
    """C on A, B alone; goal A, B, C (same start as the built-in demonstration)."""
    return BlocksworldEnv([["A", "C"], ["B"]], ["A", "B", "C"], instance_id="blocksworld/test", demo=False)


def run_recap(
    replies: list[Any], config: ReCAPConfig | None = None, env: BlocksworldEnv | None = None, demonstration: Any = False
) -> Run:
    client = ScriptedClient(replies)
    records: list[Any] = []
    agent = ReCAPAgent(config or ReCAPConfig())
    result = agent.run(env or demo_env(), client, episode_id="ep", emit=records.append, demonstration=demonstration)
    run = Run(result, client)
    for r in records:
        {MessageRecord: run.messages, CallRecord: run.calls, NodeRecord: run.nodes, StepRecord: run.steps}[type(r)].append(r)
    return run
