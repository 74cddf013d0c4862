"""ADaPT as the authors released it for Robotouille (``algorithm: plan_once``): plan once, then one
ReAct executor per subtask.

Read from GitHub ``ReCAP-Stanford/ReCAP`` at 2fb112f, ``robotouille-baselines/agents/ADaPT_agent.py``
(and ``ReAct_agent.py``, which each executor is; ``robotouille/robotouille_simulator.py``, the
loop that drives both):

* **One planner call**, at the start, in its own context (its system text, one example, then
  the observation: ADaPT_agent.py:97-159), at ``planner_temperature`` (the release's planner
  runs at 0.0, ADaPT_agent.py:21, while its executors use the configured 0.7). The reply lists
  ``Step <n>: ...`` lines and an ``Execution order:`` expression; an OR group contributes only
  its first branch, everything else runs in order (:func:`recap.baselines.textreply.parse_step_plan`,
  ADaPT_agent.py:161-235). The plan is never revised. A reply with no step ends the episode
  (ADaPT_agent.py:282-285).
* **One executor per subtask**, in order, each a fresh ReAct context (ADaPT_agent.py:237-243,
  287-302): the executor demonstration and a first message pinned, then every message is the
  current observation followed by ``Subtask: <subtask>`` (ReAct_agent.py:232-239), with error
  feedback first after an unusable reply. Replies are ``Reasoning:`` / ``Action:`` text, matched
  to the valid actions ignoring case and punctuation (:mod:`recap.baselines.textreply`). The
  executor keeps its whole history up to ``executor_window`` messages after its pins, dropping
  the oldest pair beyond *after its first reply*, which stays: each executor is a released
  ReActAgent, whose history starts with its first prompt and first reply and which trims with
  ``del truncated_history[2:4]`` once more than 64 entries are kept (ReAct_agent.py:129-130; the
  first prompt is our pin, so the kept reply is the window's first message, ``keep=1``).
* **No success check per subtask**: an executor's run ends only when it replies ``Finish``
  (ReAct_agent.py:272-274), or after ``executor_patience`` unusable replies in a row (a
  malformed reply or an action that matches none: ReAct_agent.py:229-289 gives up after 5 and
  ADaPT_agent.py:297-302 moves on). Either way the next subtask starts from the state the
  run left; nothing is rolled back, retried or re-planned.
* The episode ends on success or a cap as for every agent; otherwise with ``agent_done`` once
  the last subtask's executor stops (ADaPT_agent.py:299-301).

Demonstrations (our text): the executor's is the ReAct replies of the benchmark's script
(``replies["adapt_executor"]`` if given) played by one executor whose subtask is the
demonstration's goal; the planner's is one planner call answering with ReCAP's root
decomposition of the goal (``replies["adapt_planner"]`` if given), joined by AND.

Records: nodes ``root`` (the goal; the plan is its version) and one ``executor_task`` per
subtask, status ``done`` (Finish) / ``failed`` (gave up) / ``open`` (the episode ended in
it). Message kinds: ``planner_task`` and ``executor_task`` (pinned), ``observation``,
``feedback``. Offline doubles: ``hints["text_layout"]`` (``step_plan`` / ``reasoning_action``),
``finish_action`` and ``run_actions`` (the actions this executor run has taken).
"""

from __future__ import annotations

import dataclasses
from typing import Any

from recap.agent import DemonstrationError, format_transcript
from recap.baselines import text_prompts as T
from recap.baselines.react_text import raw_text
from recap.baselines.textreply import FINISH_ACTION, match_action, parse_reasoning_action, parse_step_plan, render
from recap.env import Demonstration, InvalidActionError, Reset
from recap.history import History
from recap.release_prompt import ReleasePrompt
from recap.runtime import Conversation, Episode, EpisodeEnd
from schemas.records import NodeVersion

EXECUTOR_FIELDS = ("think", "action")
PLANNER_FIELDS = ("think", "subtasks")
EXECUTOR_FORMAT = "Reasoning: <your reasoning>\nAction: <one valid action>"
PLANNER_FORMAT = "<reasoning>\nStep 1: <subtask>\n...\nExecution order: <AND/OR expression>"


def _keep(obj: dict[str, Any]) -> dict[str, Any]:
    return obj


def open_context(
    ep: Episode,
    *,
    temperature: Any,
    window: int | None,
    expected_format: str,
    reply_fields: tuple[str, ...],
    keep_first: bool = False,
) -> Conversation:
    """A fresh context of the episode (usage, caps and message numbering shared) with its own
    temperature and, when ``window`` is set, a window of that many messages after its pins
    (``keep_first``: its first reply is never trimmed, as the released ReAct executor keeps it)."""
    main = ep.conv
    cfg = main.config if temperature == "same" else dataclasses.replace(main.config, temperature=temperature)
    h = main.history
    history = History(
        main.episode_id,
        window if window is not None else cfg.history_window(),
        mode=cfg.window_mode,
        block=cfg.window_block,
        emit=main.emit,
        counter=h.counter,
        counts_pins=False if window is not None else cfg.history_counts_pins(),
        keep=1 if keep_first and window is not None else 0,
    )
    return Conversation(
        episode_id=main.episode_id,
        client=main.client,
        config=cfg,
        style=main.style,
        emit=main.emit,
        expected_format=expected_format,
        reply_fields=reply_fields,
        usage=main.usage,
        history=history,
    )


def _hints(ep: Episode, node: Any, role: str) -> dict[str, Any]:
    valid = ep.driver.valid_actions
    return {"role": role, "task": node.task, "depth": node.depth, "valid_actions": list(valid) if valid is not None else None}


def _release(ep: Episode, conv: Conversation, part: str) -> ReleasePrompt | None:
    """``prompts: release``: pin the authors' messages for ``part`` (``planner``: its system text
    and examples, ADaPT_agent.py:37-61; ``executor``: the executor template's and the ReAct
    examples, ADaPT_agent.py:237-243) first in ``conv``, the context just opened; the first turn
    then goes without our system text and rules. None (nothing pinned): our prompts."""
    release = ep.extra.get("release")
    if not isinstance(release, ReleasePrompt):
        return None
    for role, text in release.planner if part == "planner" else release.executor:
        conv.pin_message(role, "release", text)
    return release


def plan(agent: Any, ep: Episode, root: Any, demo: str | None) -> list[str]:
    """The one planner call: the subtasks to run, in order (OR groups cut to their first branch)."""
    cfg, d = agent.config, ep.driver
    conv = open_context(
        ep, temperature=cfg.planner_temperature, window=None, expected_format=PLANNER_FORMAT, reply_fields=PLANNER_FIELDS
    )
    release = _release(ep, conv, "planner")
    if demo:
        conv.pin("demonstration", demo)
    body = T.planner_turn(d.observation, d.goal)
    preamble = not agent.demo_mode and release is None
    conv.pin("planner_task", T.task_prompt(system=T.planner_system(), rules=ep.env.rules(), body=body, preamble=preamble))
    context = {**_hints(ep, root, "planner"), "text_layout": "step_plan"}
    raw, seq = conv.ask(None, "planner_task", _keep, node_id=root.node_id, context=context, decode=raw_text)
    subtasks = parse_step_plan(raw["text"])
    root.versions.append(NodeVersion(len(root.versions), raw["text"], tuple(subtasks), ep.conv.usage.calls - 1, seq))
    return subtasks


def execute(agent: Any, ep: Episode, node: Any, demo: str | None) -> bool:
    """One executor run on ``node``'s subtask; True when it replied Finish, False when it gave up."""
    cfg, d = agent.config, ep.driver
    conv = open_context(
        ep,
        temperature="same",
        window=cfg.executor_window,
        expected_format=EXECUTOR_FORMAT,
        reply_fields=EXECUTOR_FIELDS,
        keep_first=True,
    )
    release = _release(ep, conv, "executor")
    if demo:
        conv.pin("demonstration", demo)
    body = T.turn(d.observation, goal=d.goal, subtask=node.task)
    preamble = not agent.demo_mode and release is None
    conv.pin("executor_task", T.task_prompt(system=T.executor_system(), rules=ep.env.rules(), body=body, preamble=preamble))
    prompt: str | None = None
    kind = "executor_task"
    streak = 0
    taken: list[str] = []
    while True:
        valid = d.valid_actions
        context = {
            **_hints(ep, node, "executor"),
            "text_layout": "reasoning_action",
            "finish_action": FINISH_ACTION,
            "run_actions": list(taken),
        }
        raw, _ = conv.ask(prompt, kind, _keep, node_id=node.node_id, context=context, decode=raw_text)
        reply = parse_reasoning_action(raw["text"], with_think=True)
        feedback = reply.error
        if feedback is None and reply.finish:
            return True
        if feedback is None:
            assert reply.action is not None
            action = (match_action(reply.action, valid) if valid is not None else None) or reply.action
            try:
                d.execute(action, node.node_id)
            except InvalidActionError:
                feedback = T.invalid_action(reply.action)
            else:
                streak = 0
                taken.append(action)
                prompt, kind = T.turn(d.observation, subtask=node.task), "observation"
                continue
        streak += 1
        if cfg.executor_patience is not None and streak >= cfg.executor_patience:
            return False
        prompt, kind = T.turn(d.observation, subtask=node.task, feedback=feedback), "feedback"


def play(agent: Any, ep: Episode, reset: Reset) -> None:
    """One plan-once episode (see the module docstring)."""
    st = ep.extra
    st.update(nodes=[], max_depth=0)
    executor_demo, planner_demo = agent._demo_texts(ep)
    root = agent._new_node(ep, None, reset.goal)
    root.kind = "root"
    if agent.demo_mode and agent.demo_part == "executor":
        execute(agent, ep, root, None)
        raise EpisodeEnd("agent_done", "executor demonstration")
    subtasks = plan(agent, ep, root, planner_demo)
    if agent.demo_mode:
        raise EpisodeEnd("agent_done", "planner demonstration")
    if not subtasks:
        root.status = "failed"
        raise EpisodeEnd("agent_done", "the planner's reply lists no step")
    for task in subtasks:
        node = agent._new_node(ep, root, task)
        node.kind = "executor_task"
        node.status = "done" if execute(agent, ep, node, executor_demo) else "failed"
    root.status = "failed"
    raise EpisodeEnd("agent_done", f"the plan's {len(subtasks)} subtask(s) ran without reaching the goal")


# -- demonstrations ------------------------------------------------------------------------------------


def executor_demonstration(agent: Any, demo: Demonstration, replies: list[Any]) -> str:
    """The executor's example: ``replies`` (ReAct's, as JSON-shaped dicts) as text, one executor
    on the whole goal."""
    texts = [render("reasoning_action", r) for r in replies]
    messages, result = agent._render_run(demo, texts, "executor")
    if not result.success:
        raise DemonstrationError(
            f"demonstration {demo.name!r} does not reach the goal with the released ADaPT executor ({result.end_reason}: {result.error})"
        )
    return format_transcript(messages)


def planner_demonstration(agent: Any, demo: Demonstration, reply: dict[str, Any]) -> str:
    """The planner's example: one planner call answered with ``reply`` (think, subtasks, logic)."""
    messages, result = agent._render_run(demo, [render("step_plan", reply)], "planner")
    if result.end_reason != "agent_done" or result.llm_calls != 1:
        raise DemonstrationError(
            f"the released ADaPT planner reply of demonstration {demo.name!r} is not usable ({result.end_reason}: {result.error})"
        )
    prompt, text = (m.content for m in messages)
    return T.planner_example(prompt, text)
