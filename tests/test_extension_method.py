"""Adding a method touches only the method: a toy method defined in this file runs a real unit.

The toy, ``toy_replan``, asks for the whole plan, runs it, and asks again from where it stopped
(an invalid action, or the plan running out before the goal). It is registered with
``recap.methods.register_method`` for the duration of the test, then plays one offline
expert-driven episode on a real benchmark (blocksworld) through the episode worker's
``EpisodeRunner.run_unit`` and the litellm ``offline/expert`` test double - the path a sweep
takes. Nothing in the repository names it (checked below).

A real new method would touch:

* ``recap/<method>.py`` (or ``recap/baselines/<method>.py``): the agent class and its config
  class - the prompts it sends, ``play``, and its declarations: ``style`` (its name),
  ``expected_format`` and ``reply_fields`` (what the offline test doubles fill),
  ``demo_replies(script)`` (its demonstration replies, derived from each benchmark's
  ``DemoScript``), ``calls_per_step`` / ``call_overhead`` (call cap), ``one_shot`` /
  ``estimate_calls_per_step`` (``recap estimate``);
* its prompts module, if it has its own (``recap/baselines/prompts.py`` for the baselines);
* ``recap/method_registry.py``: one line in the table of built-ins,
  ``METHODS.register("<name>", ("recap.<module>:<Agent>", "recap.<module>:<Config>"))`` (a
  plug-in calls ``recap.methods.register_method`` instead, or decorates its agent class with
  ``@METHODS.register("<name>")``), the one list of method names;
* its tests (``tests/recap/``).

No benchmark's demonstration module, offline test double, estimate table or worker changes.
"""

from __future__ import annotations

import json
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from recap.agent import Agent
from recap.config import AgentConfig, ConfigError
from recap.demo_script import DemoScript
from recap.env import InvalidActionError, Reset
from recap.jsonreply import plan_reply
from recap.methods import METHODS, registered_method
from recap.runtime import Episode, EpisodeEnd
from schemas.outcomes import UnitWork

NAME = "toy_replan"
REPO = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class ReplanConfig(AgentConfig):
    """How many plans the toy may ask for."""

    max_plans: int = 3

    def validate(self) -> None:
        super().validate()
        if self.max_plans < 1:
            raise ConfigError("max_plans must be >= 1")


class ReplanAgent(Agent):
    """Ask for the whole plan, run it, ask again from where it stopped."""

    style = NAME
    config_cls = ReplanConfig
    config: ReplanConfig
    expected_format = '{"think": "<reasoning>", "actions": ["<action>", ...]}'
    reply_fields = ("think", "actions")
    calls_per_step = 0.5
    call_overhead = 2

    @classmethod
    def demo_replies(cls, script: DemoScript) -> list[dict[str, Any]]:
        return [{"think": script.plan_thought, "actions": list(script.actions)}]

    def play(self, ep: Episode, reset: Reset) -> None:
        head = [] if self.demo_mode else [f"Rules:\n{ep.env.rules()}"]
        ep.conv.pin(
            "task",
            "\n\n".join(
                [*head, f"Goal: {reset.goal}", f"State:\n{reset.observation}", f"Reply with a plan: {self.expected_format}"]
            ),
        )
        prompt: str | None = None
        for _ in range(self.config.max_plans):
            reply, _seq = ep.conv.ask(
                prompt,
                "plan" if prompt is None else "replan",
                lambda o: plan_reply(o, with_think=True),
                context={"task": reset.goal, "depth": 0, "valid_actions": list(ep.driver.valid_actions or [])},
            )
            stopped = "the plan ran out"
            for action in reply["actions"]:
                try:
                    ep.driver.execute(action)
                except InvalidActionError:
                    stopped = f"'{action}' is not a valid action"
                    break
            prompt = f"The plan stopped: {stopped}. State:\n{ep.driver.observation}\n\nReply with a new plan."
        raise EpisodeEnd("agent_done", f"{self.config.max_plans} plans did not reach the goal")


class _Factory:
    """The driver's client factory, reduced to the litellm offline provider (no gateway)."""

    writes_llm_calls = False

    def client(self, model_label: str) -> Any:
        from workers.llm.direct import LiteLLMClient
        from workers.llm.providers import DeploymentConfig

        return LiteLLMClient(DeploymentConfig(model="offline/expert", offline_options={"seed": 1, "invalid_action_rate": 0.0}))


def _git_status() -> str:
    return subprocess.run(["git", "status", "--porcelain"], cwd=REPO, capture_output=True, text=True, check=True).stdout


def _run(config: ReplanConfig) -> tuple[Any, dict[str, list[dict]]]:
    from workers.episode_worker import EpisodeRunner

    rows: dict[str, list[dict]] = {}

    def send(batch: dict[str, list[dict]]) -> None:
        for table, items in batch.items():
            rows.setdefault(table, []).extend(items)

    runner = EpisodeRunner("w1", "run-x", _Factory(), send=send, wait=lambda _ref: None)
    work = UnitWork(
        unit_id="u1",
        instance_id="blocksworld/3@1",
        method=NAME,
        method_config=config.to_json(),
        model_label="expert",
        model="offline/expert",
        sampling_seed=1,
        step_multiplier=4.0,
    )
    return runner.run_unit(work, 1), rows


DEMO = (
    "Here is a complete example of the interaction, from the first prompt to the goal being reached.\n\n"
    "[Example prompt]\nGoal: Build one tower with A on the table, then B on A, then C on B.\n\n"
    "State:\nTower on the table: A, C (top: C)\nTower on the table: B (top: B)\nThe gripper is empty.\n"
    "Valid Actions:\npick up B\nunstack C from A\n\n"
    'Reply with a plan: {"think": "<reasoning>", "actions": ["<action>", ...]}\n\n'
    '[Example reply]\n{"think": "C blocks A, so move C to the table, then stack B on A and C on B.", '
    '"actions": ["unstack C from A", "put down C", "pick up B", "stack B on A", "pick up C", "stack C on B"]}\n\n'
    "[End of example: the goal was reached.]"
)


TASK = (
    "Rules:\nThere are lettered blocks standing in towers on a table, and one gripper.\n"
    "- The gripper holds at most one block at a time.\n"
    "- Only a clear block (nothing on top of it) can be picked up or unstacked.\n"
    "- 'pick up X' takes a clear block X from the table; 'unstack X from Y' takes X off block Y.\n"
    "- 'put down X' places the held block on the table; 'stack X on Y' places it on a clear block Y.\n"
    "- The goal names one tower from the bottom up; other blocks may be anywhere.\n\n"
    "Goal: Build one tower with C on the table, then A on C, then B on A.\n\n"
    "State:\nTower on the table: A, C, B (top: B)\nThe gripper is empty.\nValid Actions:\nunstack B from C\n\n"
    'Reply with a plan: {"think": "<reasoning>", "actions": ["<action>", ...]}'
)


def test_a_method_defined_outside_the_repository_runs_a_unit():
    assert NAME not in METHODS
    before = _git_status()
    with registered_method(NAME, ReplanAgent, ReplanConfig):
        outcome, rows = _run(ReplanConfig())
    assert NAME not in METHODS  # undone
    assert _git_status() == before  # running it wrote nothing into the repository either

    assert outcome.crash is None
    r = outcome.result
    assert (r.end_reason, r.success, r.steps, r.llm_calls, r.invalid_actions, r.json_repairs, r.error) == (
        "success",
        True,
        10,
        1,
        0,
        0,
        None,
    )
    assert (outcome.model, outcome.test_double) == ("offline/expert", True)
    assert (outcome.env.benchmark, outcome.env.split, outcome.env.task, outcome.env.max_steps) == (
        "blocksworld",
        "3_blocks",
        "tower_CAB",
        40,
    )

    messages = [(m["seq"], m["role"], m["kind"], m["pinned"]) for m in rows["messages"]]
    assert messages == [(0, "user", "demonstration", True), (1, "user", "task", True), (2, "assistant", "reply", False)]
    text = {m["seq"]: m["content"] for m in rows["messages"]}
    # the demonstration: the toy's own prompt and the reply it derived from blocksworld's script
    assert text[0] == DEMO
    assert text[1] == TASK
    plan = [
        "unstack B from C",
        "put down B",
        "unstack C from A",
        "put down C",
        "pick up C",
        "put down C",
        "pick up A",
        "stack A on C",
        "pick up B",
        "stack B on A",
    ]
    # the offline expert answered the fields the toy declared, knowing nothing else about it
    assert json.loads(text[2]) == {"think": "Expert plan: 10 action(s) left.", "actions": plan}
    assert [(s["index"], s["env_step"], s["action"], s["valid"], s["success"]) for s in rows["steps"]] == [
        (i, i + 1, a, True, i == len(plan) - 1) for i, a in enumerate(plan)
    ]
    assert [(c["call_index"], c["purpose"], c["status"], c["model"]) for c in rows["llm_calls"]] == [
        (0, "plan", "ok", "offline/expert")
    ]
    assert sorted(rows) == ["llm_calls", "messages", "steps"]


def test_the_toy_replans_after_an_invalid_action():
    with registered_method(NAME, ReplanAgent, ReplanConfig):
        agent = METHODS[NAME][0](ReplanConfig())
        from recap.blocksworld import BENCHMARK
        from recap.scripted import ScriptedClient

        env = BENCHMARK.make("blocksworld/3@1")
        client = ScriptedClient([{"think": "x", "actions": ["fly away"]}, {"think": "y", "actions": env.expert_plan()}])
        result = agent.run(env, client, demonstration=False)
    assert (result.end_reason, result.llm_calls, result.invalid_actions) == ("success", 2, 1)
    assert [r.purpose for r in client.requests] == ["plan", "replan"]
    assert client.requests[1].messages[-1].content.startswith("The plan stopped: 'fly away' is not a valid action. State:\n")
    assert client.requests[0].hints["reply_fields"] == ("think", "actions")


def test_nothing_in_the_repository_names_the_toy_method():
    """The toy needed no edit anywhere: no source file outside this test mentions it."""
    tracked = subprocess.run(
        ["git", "ls-files", "*.py", "*.yaml", "*.md"], cwd=REPO, capture_output=True, text=True, check=True
    ).stdout.split()
    here = Path(__file__).resolve()
    named = [
        p
        for p in tracked
        if (REPO / p).resolve() != here
        and (REPO / p).is_file()
        and ("ReplanAgent" in (REPO / p).read_text(errors="replace") or f'"{NAME}"' in (REPO / p).read_text(errors="replace"))
    ]
    assert named == []


def test_the_toy_config_is_checked():
    with pytest.raises(ConfigError, match="max_plans must be >= 1"):
        ReplanConfig(max_plans=0).validate()
