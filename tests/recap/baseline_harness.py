"""Helpers for the baseline tests: run any agent on a scripted model, split the records, and
build expected observations by replaying actions on a fresh blocksworld environment."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from recap.agent import Agent
from recap.blocksworld import BlocksworldEnv
from recap.env import Step
from recap.runtime import EpisodeResult
from recap.scripted import ScriptedClient
from schemas.records import CallRecord, MessageRecord, NodeRecord, StepRecord

GOAL = "Build one tower with A on the table, then B on A, then C on B."
DEMO_ACTIONS = ["unstack C from A", "put down C", "pick up B", "stack B on A", "pick up C", "stack C on B"]


@dataclass
class Run:
    result: EpisodeResult
    client: ScriptedClient
    messages: list[MessageRecord] = field(default_factory=list)
    calls: list[CallRecord] = field(default_factory=list)
    nodes: list[NodeRecord] = field(default_factory=list)
    steps: list[StepRecord] = field(default_factory=list)

    def seq(self) -> list[tuple[int, str, str, bool]]:
        return [(m.seq, m.role, m.kind, m.pinned) for m in self.messages]

    def content(self, seq: int) -> str:
        return next(m.content for m in self.messages if m.seq == seq)

    def windows(self) -> list[tuple[int, ...]]:
        return [r.window_seqs for r in self.client.requests]


def demo_env(**kw: Any) -> BlocksworldEnv:
    """C on A, B alone; goal A, B, C (the start of the built-in demonstration)."""
    return BlocksworldEnv([["A", "C"], ["B"]], ["A", "B", "C"], instance_id="blocksworld/test", demo=False, **kw)


class SteppingBlocksworld(BlocksworldEnv):
    """Blocksworld that, like ALFWorld, lets any command reach the game: an action that is not
    valid takes a step and is answered "Nothing happens."."""

    invalid_action_mode = "step"
    #: its "Nothing happens." lists no valid actions
    lists_valid_actions = False

    def step(self, action: str) -> Step:
        if action in self._valid:
            return super().step(action)
        self._steps_taken += 1
        return Step("Nothing happens.", self._valid, self._steps_taken >= self.max_steps, False, {})


def stepping_env() -> SteppingBlocksworld:
    return SteppingBlocksworld([["A", "C"], ["B"]], ["A", "B", "C"], instance_id="blocksworld/step", demo=False)


def obs_after(*actions: str) -> str:
    """The environment's own observation after ``actions`` from the demo start."""
    env = demo_env()
    obs = env.reset().observation
    for a in actions:
        obs = env.step(a).observation
    return obs


def run_agent(agent: Agent, replies: list[Any], env: BlocksworldEnv | None = None, demonstration: Any = False) -> Run:
    client = ScriptedClient(replies)
    records: list[Any] = []
    result = agent.run(env or demo_env(), client, episode_id="ep", emit=records.append, demonstration=demonstration)
    run = Run(result, client)
    for r in records:
        {MessageRecord: run.messages, CallRecord: run.calls, NodeRecord: run.nodes, StepRecord: run.steps}[type(r)].append(r)
    return run
