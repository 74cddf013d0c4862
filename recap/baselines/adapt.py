"""ADaPT (Prasad et al., 2023, "As-Needed Decomposition and Planning with Language Models").

``algorithm: plan_once`` (the ``released`` profile outside ALFWorld) is instead the authors'
released Robotouille ADaPT, which plans once and never decomposes on failure:
:mod:`recap.baselines.adapt_released`. Everything below is ``algorithm: as_needed``.

Control flow (the paper's Algorithm 1, with the released code's depth rule):

    solve(task, depth):
        if executor(task) reports done:   return success      # try first, plan only on failure
        if depth == max_depth:            return failure      # deepest tasks are never decomposed
        subtasks, logic = planner(task)                       # one call
        AND: run the subtasks in order, stop at the first failure; success iff all succeed
        OR:  run the subtasks in order, stop at the first success; success iff one succeeds

The root task (the goal) is depth 1; with ``max_depth=3`` (the paper's setting) decompositions
happen at depths 1 and 2. Subtasks are created and run only when reached (as needed).

* The **executor** is a ReAct-style agent in its own isolated context: a fresh
  :meth:`~recap.runtime.Conversation.fork` per run (the root's run uses the episode's main
  context), with the executor demonstration and its task prompt pinned. The task prompt shows
  only that task, the current observation and the last action taken (ADaPT passes the last
  step on to the next executor), and, once the state has moved on, the episode's first
  observation (the reset observation) when the environment is partially observed
  (``Environment.partially_observed``, e.g. ALFWorld: an executor opened for a subtask would
  otherwise never see the room description and the goal; ADaPT's ALFWorld code gives each
  prompt the room description). On a fully observed environment (Robotouille) the current
  observation already shows the whole state and the first one is left out, unless
  ``initial_observation`` asks for it (that option also adds it to planner prompts).
  Each reply is ``{"think", "action"}`` (handled exactly like ReAct: exact lookup, error
  feedback in ``reject`` mode, pass-through in ``step`` mode) or ``{"think", "status"}`` with
  ``"done"`` / ``"failed"`` — ADaPT's "Task completed!" / "Task failed!". A run fails when it
  reports failure, uses up ``executor_steps`` replies without a status (the released code
  allows 20 commands per run), or makes ``executor_patience`` invalid actions in a row (the
  released code stops after 5 actions in a row that change nothing).
* The **planner** is one call in a fresh isolated context: ``{"think", "subtasks", "logic"}``
  with ``logic`` ``"and"`` or ``"or"`` (default ``"and"`` when left out, as the released code
  falls back to AND). Nested AND/OR expressions are not supported (ADaPT's own ALFWorld
  prompt tells the model to avoid OR). An empty list fails the task.
* The environment is **not** rolled back after a failed executor run, and a failed executor's
  actions are not undone (the released ALFWorld code resets the game and replays the
  successful actions). This is deliberate: every agent here plays one uninterrupted pass@1
  trajectory under the same step budget, and a rollback would replay steps outside it. Later
  executors and planners start from the state the failed attempt left, which their prompts show.
* Demonstrations: the executor's is rendered by running this agent on the demonstration
  environment with hand-written ``replies["adapt_executor"]`` if present, else the ReAct
  replies (derived from the demonstration's script: the root executor solves the demo); the
  planner's is one planner call at the demonstration's start, replying
  ``replies["adapt_planner"][0]`` if present, else ReCAP's root decomposition
  (``replies["recap"][0]``: the script's first decomposition, think and subtasks) with
  ``"logic": "and"``. ADaPT derives no single reply list of its own
  (:meth:`~recap.agent.Agent.demo_replies` is None). A demonstration given as a string is
  pinned as is in every executor and planner context.
* Offline test doubles: executor contexts declare ``reply_fields`` ``("think", "action")``,
  planner contexts ``("think", "subtasks")`` (repairs included), see ``hints["reply_fields"]``.
* Records: messages of every context (one shared seq counter), calls, steps (``node_id`` = the
  task node), and one tree node per task: ``root``, ``composite`` (decomposed) or
  ``primitive`` (left to the executor), status ``done`` / ``failed`` / ``open``, with the
  planner's reply as the node's version. ``EpisodeResult.max_depth`` is the deepest node with
  the root at 0, as for ReCAP.
* Message kinds (also the call purposes): executor ``executor_task`` (pinned), ``observation``,
  ``feedback``; planner ``planner_task`` (pinned); ``repair`` in either. The hints add
  ``role`` (``executor`` / ``planner``) to ``task`` (the node's task), ``depth`` and
  ``valid_actions``.
* The episode ends with ``success`` as soon as the environment reports it, otherwise with
  ``agent_done`` once the root task is settled (reported done without the environment agreeing,
  or failed at every depth), or with a cap / error like every agent.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

from recap.agent import Agent, DemonstrationError, format_transcript
from recap.baselines import adapt_released
from recap.baselines import prompts as P
from recap.baselines.react import ReActAgent
from recap.config import AgentConfig, ConfigError
from recap.env import Demonstration, Environment, InvalidActionError, Reset
from recap.history import History
from recap.jsonreply import ReplyFormatError, action_reply, recap_reply
from recap.recap_agent import ReCAPAgent
from recap.runtime import Conversation, Episode, EpisodeEnd
from recap.tree import Node
from schemas.kinds import NodeKind
from schemas.records import MessageRecord, NodeVersion

_DEMOS: dict[tuple[str, ...], str] = {}
#: the fields of an executor's and a planner's reply, as the offline test doubles fill them
EXECUTOR_REPLY_FIELDS = ("think", "action")
PLANNER_REPLY_FIELDS = ("think", "subtasks")
#: keys of hand-written ADaPT replies in a Demonstration (they win over the derived ones)
EXECUTOR_DEMO_KEY = "adapt_executor"
PLANNER_DEMO_KEY = "adapt_planner"


#: what ``released`` sets for ADaPT: the authors' released (Robotouille) algorithm; a benchmark
#: whose release has no ADaPT drops it in its protocol (ALFWorld)
RELEASED_PLAN_ONCE: dict[str, Any] = {
    "algorithm": "plan_once",
    "json_mode": False,
    "planner_temperature": 0.0,
    "executor_window": 64,
    "executor_patience": 5,
}


@dataclass(frozen=True)
class ADaPTConfig(AgentConfig):
    """ADaPT settings. ``max_depth``: deepest task level (root = 1; the paper uses 3);
    ``executor_steps``: replies one executor run may take; ``executor_patience``: invalid
    actions in a row that end an executor run as failed (None: no limit);
    ``initial_observation``: also show the episode's first observation in executor and planner
    prompts once the state has moved on, on any environment (executor prompts on a partially
    observed environment show it whatever this says)."""

    max_depth: int = 3
    executor_steps: int = 20
    executor_patience: int | None = 5
    initial_observation: bool = False
    #: ``as_needed``: the ADaPT paper's execute-first / decompose-on-failure (this module);
    #: ``plan_once``: the authors' released Robotouille ADaPT (recap.baselines.adapt_released),
    #: plain-text replies, so it needs ``json_mode: false``
    algorithm: Literal["as_needed", "plan_once"] = "as_needed"
    #: plan_once: the planner call's temperature ("same": the agent's ``temperature``)
    planner_temperature: float | None | Literal["same"] = "same"
    #: plan_once: messages an executor keeps after its pins (None: the agent's window rules)
    executor_window: int | None = None

    @classmethod
    def profile_defaults(cls, profile: str, ablation: str | None) -> dict[str, Any]:
        out = super().profile_defaults(profile, ablation)
        if profile == "released":
            # the release's ADaPT (Robotouille's; ALFWorld's protocol keeps the paper's
            # algorithm, the release having no ADaPT there): plan once at temperature 0.0
            # (ADaPT_agent.py:21), executors trimmed past 64 messages (ReAct_agent.py:129) and
            # given up after 5 unusable replies in a row (ReAct_agent.py:62,231)
            out.update(RELEASED_PLAN_ONCE)
        return out

    def validate(self) -> None:
        super().validate()
        if self.algorithm not in ("as_needed", "plan_once"):
            raise ConfigError(f"algorithm must be as_needed or plan_once, got {self.algorithm!r}")
        if self.algorithm == "plan_once" and self.json_mode:
            raise ConfigError("algorithm: plan_once needs json_mode: false (its replies are plain text)")
        t = self.planner_temperature
        if t != "same" and t is not None and (isinstance(t, bool) or not isinstance(t, int | float) or not 0 <= t <= 2):
            raise ConfigError(f'planner_temperature must be in [0, 2], null or "same", got {t!r}')
        if self.executor_window is not None and self.executor_window < 2:
            raise ConfigError(f"executor_window must be >= 2 messages or null, got {self.executor_window}")
        if self.max_depth < 1:
            raise ConfigError(f"max_depth must be >= 1 (the root task is depth 1), got {self.max_depth}")
        if self.executor_steps < 1:
            raise ConfigError(f"executor_steps must be >= 1, got {self.executor_steps}")
        if self.executor_patience is not None and self.executor_patience < 1:
            raise ConfigError(f"executor_patience must be >= 1 or null, got {self.executor_patience}")


def fork(conv: Conversation, expected_format: str, reply_fields: tuple[str, ...]) -> Conversation:
    """``conv.fork()`` with the message counter really shared.

    Works around ``Conversation.__init__`` taking ``history or History(...)``: an empty History
    has length 0, is falsy, and the fork's counter-sharing history is replaced by a fresh one
    (message seqs would restart at 0). A no-op once that is fixed.
    """
    forked = conv.fork(expected_format=expected_format, reply_fields=reply_fields)
    if forked.history.counter is not conv.history.counter:
        h = conv.history
        forked.history = History(
            conv.episode_id, h.window, mode=h.mode, block=h.block, emit=conv.emit, counter=h.counter, counts_pins=h.counts_pins
        )
    return forked


# -- reply shapes -----------------------------------------------------------------------------------


def executor_reply(obj: Mapping[str, Any]) -> dict[str, Any]:
    """{"think", "action"} to act, or {"think", "status": "done"|"failed"} to finish."""
    status = obj.get("status")
    if status is None:
        reply = action_reply(obj, with_think=True)
        return {**reply, "status": None}
    if not isinstance(status, str) or status.strip().lower() not in ("done", "failed"):
        raise ReplyFormatError('"status" must be "done" or "failed" (leave it out to take an action)')
    think = obj.get("think")
    if not isinstance(think, str):
        raise ReplyFormatError('the JSON object needs a "think" field (a string)')
    if obj.get("action") not in (None, ""):
        raise ReplyFormatError('give either an "action" or a "status", not both')
    return {"think": think, "action": None, "status": status.strip().lower()}


def planner_reply(obj: Mapping[str, Any]) -> dict[str, Any]:
    """{"think", "subtasks": [...], "logic": "and"|"or"} (logic defaults to "and")."""
    reply = recap_reply(obj, with_think=True)
    logic = obj.get("logic", "and")
    if not isinstance(logic, str) or logic.strip().lower() not in ("and", "or"):
        raise ReplyFormatError('"logic" must be "and" or "or"')
    subtasks = tuple(s for s in reply["subtasks"] if s)
    return {"think": reply["think"], "subtasks": subtasks, "logic": logic.strip().lower()}


# -- the task tree ------------------------------------------------------------------------------------


@dataclass
class TaskNode(Node):
    """An ADaPT task: executed first, decomposed (with AND/OR logic) only when it fails."""

    kind: NodeKind = "primitive"
    logic: str | None = None


class ADaPTAgent(Agent):
    """ADaPT: an executor tries each task action by action and, only when it fails, a planner splits
    the task into and/or subtasks, recursively up to ``max_depth`` (see the module docstring).
    Executor runs and planner calls each get their own context."""

    style = "adapt"
    config_cls = ADaPTConfig
    expected_format = P.EXECUTOR_FORMAT
    config: ADaPTConfig
    #: an executor call per action, plus planner calls, status replies and rejected actions
    calls_per_step = 3.0
    estimate_calls_per_step = (1.0, 3.0)
    #: executor calls ask for the next action (the offline doubles never report a status);
    #: planner calls (their own contexts) for subtasks
    reply_fields = EXECUTOR_REPLY_FIELDS

    def __init__(self, config: ADaPTConfig | None = None) -> None:
        super().__init__(config)
        #: which part a demonstration run renders: "executor" (the whole agent) or "planner"
        self.demo_part = "executor"

    # -- one episode ------------------------------------------------------------------------------
    def play(self, ep: Episode, reset: Reset) -> None:
        if self.config.algorithm == "plan_once":
            return adapt_released.play(self, ep, reset)
        st = ep.extra
        st.update(nodes=[], max_depth=0, rules=ep.env.rules(), initial=reset.observation, last_action=None)
        st["executor_demo"], st["planner_demo"] = self._demo_texts(ep)
        root = self._new_node(ep, None, reset.goal)
        root.kind = "root"
        if self.demo_mode and self.demo_part == "planner":
            self._plan(ep, root)
            raise EpisodeEnd("agent_done", "planner demonstration")
        if self._solve(ep, root):
            raise EpisodeEnd("agent_done", "the goal was reported done but the environment does not confirm it")
        raise EpisodeEnd("agent_done", "the goal failed at every depth")

    def _new_node(self, ep: Episode, parent: TaskNode | None, task: str) -> TaskNode:
        st = ep.extra
        depth = 0 if parent is None else parent.depth + 1
        node = TaskNode(len(st["nodes"]), parent, depth, parent.n_children if parent else 0, task)
        if parent is not None:
            parent.n_children += 1
        st["nodes"].append(node)
        st["max_depth"] = max(st["max_depth"], depth)
        return node

    def _solve(self, ep: Episode, node: TaskNode) -> bool:
        """ADaPT(task, depth): execute first; decompose only on failure, above the depth cap."""
        if self._execute(ep, node):
            node.status = "done"
            return True
        if node.depth + 1 >= self.config.max_depth:
            node.status = "failed"
            return False
        subtasks, logic = self._plan(ep, node)
        if node.kind != "root":
            node.kind = "composite"
        node.logic = logic
        ok = False
        if subtasks:
            ok = logic == "and"
            for sub in subtasks:
                child_ok = self._solve(ep, self._new_node(ep, node, sub))
                if logic == "and" and not child_ok:
                    ok = False
                    break
                if logic == "or" and child_ok:
                    ok = True
                    break
        node.status = "done" if ok else "failed"
        return ok

    # -- executor ---------------------------------------------------------------------------------
    def _situation(self, ep: Episode, role: str) -> dict[str, Any]:
        """What a task prompt shows. The episode's first observation is added once the state
        has moved on (before that it is the current observation): for every executor on a
        partially observed environment, and for every prompt with ``initial_observation``."""
        st = ep.extra
        moved = st["last_action"] is not None
        initial = self.config.initial_observation or (role == "executor" and ep.env.partially_observed)
        return {
            "rules": st["rules"],
            "observation": ep.driver.observation,
            "last_action": st["last_action"],
            "initial_observation": st["initial"] if initial and moved else None,
            "preamble": not self.demo_mode,
        }

    def _context(self, ep: Episode, node: TaskNode, role: str) -> dict[str, Any]:
        valid = ep.driver.valid_actions
        return {"role": role, "task": node.task, "depth": node.depth, "valid_actions": list(valid) if valid is not None else None}

    def _open(
        self, ep: Episode, node: TaskNode | None, demo: str | None, expected_format: str, reply_fields: tuple[str, ...]
    ) -> Conversation:
        """The root executor works in the episode's main context (its demonstration is already
        pinned there); every other executor run and every planner call gets a fresh one."""
        if node is not None and node.parent is None:
            return ep.conv
        conv = fork(ep.conv, expected_format, reply_fields)
        if demo:
            conv.pin("demonstration", demo)
        return conv

    def _execute(self, ep: Episode, node: TaskNode) -> bool:
        cfg, st, d = self.config, ep.extra, ep.driver
        conv = self._open(ep, node, st["executor_demo"], P.EXECUTOR_FORMAT, EXECUTOR_REPLY_FIELDS)
        conv.pin("executor_task", P.executor_task_prompt(task=node.task, **self._situation(ep, "executor")))
        prompt: str | None = None
        kind = "executor_task"
        streak = 0
        for _ in range(cfg.executor_steps):
            reply, _seq = conv.ask(
                prompt, kind, executor_reply, node_id=node.node_id, context=self._context(ep, node, "executor")
            )
            if reply["status"] is not None:
                return reply["status"] == "done"
            action = reply["action"]
            was_valid = d.is_valid(action)
            try:
                d.execute(action, node.node_id)
            except InvalidActionError:
                prompt, kind = P.invalid_action_prompt(action, d.observation), "feedback"
                streak += 1
            else:
                st["last_action"] = action
                prompt, kind = P.observation_prompt(d.observation), "observation"
                streak = 0 if was_valid else streak + 1
            if cfg.executor_patience is not None and streak >= cfg.executor_patience:
                return False
        return False

    # -- planner ----------------------------------------------------------------------------------
    def _plan(self, ep: Episode, node: TaskNode) -> tuple[tuple[str, ...], str]:
        conv = self._open(ep, None, ep.extra["planner_demo"], P.PLANNER_FORMAT, PLANNER_REPLY_FIELDS)
        conv.pin("planner_task", P.planner_task_prompt(task=node.task, **self._situation(ep, "planner")))
        reply, seq = conv.ask(
            None, "planner_task", planner_reply, node_id=node.node_id, context=self._context(ep, node, "planner")
        )
        node.versions.append(NodeVersion(len(node.versions), reply["think"], reply["subtasks"], ep.conv.usage.calls - 1, seq))
        return reply["subtasks"], reply["logic"]

    # -- end of episode ---------------------------------------------------------------------------
    def max_depth(self, ep: Episode) -> int:
        return int(ep.extra.get("max_depth", 0))

    def finish(self, ep: Episode) -> None:
        for node in ep.extra.get("nodes", []):
            ep.emit(node.record(ep.conv.episode_id))

    # -- demonstrations ---------------------------------------------------------------------------
    def demo_config(self) -> ADaPTConfig:
        cfg = super().demo_config()
        assert isinstance(cfg, ADaPTConfig)
        return dataclasses.replace(cfg, executor_steps=100_000, executor_patience=None)

    def demonstration_text(self, env: Environment) -> str | None:
        """The executor's demonstration (pinned in the main context); the planner's is rendered
        too, so a demonstration that does not work fails before the episode starts."""
        demo = env.demonstration()
        if demo is None:
            return None
        text = self.render_demonstration(demo)
        self.render_planner_demonstration(demo)
        return text

    def _key(self, part: str, demo: Demonstration) -> tuple[str, ...]:
        return (part, type(self).__name__, demo.name, self.config.to_json())

    def render_demonstration(self, demo: Demonstration) -> str:
        key = self._key("executor", demo)
        if key not in _DEMOS and self.config.algorithm == "plan_once":
            released = demo.replies.get(EXECUTOR_DEMO_KEY) or demo.replies.get(ReActAgent.style)
            if released is None:
                raise DemonstrationError(
                    f"demonstration {demo.name!r} has no 'adapt_executor' or 'react' replies for the ADaPT executor"
                )
            _DEMOS[key] = adapt_released.executor_demonstration(self, demo, list(released))
        if key not in _DEMOS:
            replies = demo.replies.get(EXECUTOR_DEMO_KEY) or demo.replies.get(ReActAgent.style)
            if replies is None:
                raise DemonstrationError(
                    f"demonstration {demo.name!r} has no 'adapt_executor' or 'react' replies for the ADaPT executor"
                )
            messages, result = self._render_run(demo, list(replies), "executor")
            if not result.success:
                raise DemonstrationError(
                    f"demonstration {demo.name!r} does not reach the goal with the ADaPT executor ({result.end_reason}: {result.error})"
                )
            _DEMOS[key] = format_transcript(messages)
        return _DEMOS[key]

    def render_planner_demonstration(self, demo: Demonstration) -> str:
        key = self._key("planner", demo)
        if key not in _DEMOS and self.config.algorithm == "plan_once":
            _DEMOS[key] = adapt_released.planner_demonstration(self, demo, planner_demo_reply(demo))
        if key not in _DEMOS:
            messages, result = self._render_run(demo, [planner_demo_reply(demo)], "planner")
            if result.end_reason != "agent_done" or result.llm_calls != 1:
                raise DemonstrationError(
                    f"the ADaPT planner reply of demonstration {demo.name!r} is not usable ({result.end_reason}: {result.error})"
                )
            prompt, reply = (m.content for m in messages)
            _DEMOS[key] = P.planner_transcript(prompt, reply)
        return _DEMOS[key]

    def _render_run(self, demo: Demonstration, replies: list[Any], part: str) -> tuple[list[MessageRecord], Any]:
        def play_part(agent: Agent) -> None:
            assert isinstance(agent, ADaPTAgent)
            agent.demo_part = part

        return self.scripted_demo_run(demo, replies, f"demo:{demo.name}:{part}", play_part)

    def _demo_texts(self, ep: Episode) -> tuple[str | None, str | None]:
        """(executor demonstration, planner demonstration) for this episode's contexts."""
        pinned = [e.message.content for e in ep.conv.history.entries() if e.pinned and e.kind == "demonstration"]
        if not pinned:
            return None, None
        text = pinned[0]
        demo = ep.env.demonstration()
        if demo is not None and _DEMOS.get(self._key("executor", demo)) == text:
            return text, self.render_planner_demonstration(demo)
        return text, text


def planner_demo_reply(demo: Demonstration) -> dict[str, Any]:
    """The planner's demonstration reply: ``adapt_planner`` if the demonstration has one, else
    ReCAP's root decomposition of the same goal, combined with AND."""
    if demo.replies.get(PLANNER_DEMO_KEY):
        return dict(demo.replies[PLANNER_DEMO_KEY][0])
    recap = demo.replies.get(ReCAPAgent.style)
    if not recap:
        raise DemonstrationError(
            f"demonstration {demo.name!r} has no 'adapt_planner' or 'recap' replies to derive the ADaPT planner's example"
        )
    first = recap[0]
    return {"think": first.get("think") or "", "subtasks": list(first["subtasks"]), "logic": "and"}
