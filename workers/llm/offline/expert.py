"""TEST DOUBLE ``offline/expert``: replies that follow the environment's expert plan.

Why: it drives every agent (ReCAP and the flat baselines) to success through the real agent
code, prompts and records, without a model - the end-to-end check of the pipeline. It reads
only the hints the episode worker attaches (see recap/recap_agent.py), never the prompt:

- ``style``: recap | react | act | cot | standard | adapt;
- ``purpose``: which prompt this is (``task``, ``descend``, refine kinds, ``depth_cap`` ...);
- ``task``, ``depth``, ``remaining`` (the node's current list), ``valid_actions``;
- ``expert_plan``: the remaining expert actions from the current environment state.

ReCAP replies (the call order of recap/recap_agent.py):
- root (``task``): the remaining plan grouped into a few subgoal chunks, each named
  ``subgoal <k>: <action>; <action>; ...`` (a one-action chunk is named by the action itself,
  so the agent takes its shortcut);
- ``descend`` into a chunk: the chunk's actions that are still on the plan;
- ``depth_cap``: the next expert action;
- any other purpose is a refinement: the items of ``remaining`` that are still on the plan,
  in order; ``[]`` when none is (the node is done). At the root, plan left over after the
  kept items is appended as new chunks, and ``[]`` is returned only when the plan is empty.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from typing import Any

from workers.llm.offline.knobs import INVALID_ACTION, Knobs, draw

CHUNK_PREFIX = "subgoal"
_CHUNK_RE = re.compile(rf"^{CHUNK_PREFIX} (\d+): (.+)$")
ACTION_SEPARATOR = "; "
MAX_ROOT_CHUNKS = 4
#: action used by flat styles when the plan is empty and no valid actions are known
FALLBACK_ACTION = "look"


def chunk_name(index: int, actions: Sequence[str]) -> str:
    if len(actions) == 1:
        return actions[0]
    return f"{CHUNK_PREFIX} {index}: " + ACTION_SEPARATOR.join(actions)


def chunk_actions(name: str) -> list[str] | None:
    """The actions a chunk name lists, or None when ``name`` is not a chunk name."""
    m = _CHUNK_RE.match(name)
    if m is None:
        return None
    return m.group(2).split(ACTION_SEPARATOR)


def group_plan(plan: Sequence[str], chunk_size: int | None = None) -> list[str]:
    """The plan as named chunks (at most MAX_ROOT_CHUNKS unless chunk_size is given)."""
    plan = list(plan)
    if not plan:
        return []
    size = chunk_size or math.ceil(len(plan) / MAX_ROOT_CHUNKS)
    return [chunk_name(k + 1, plan[i:i + size]) for k, i in enumerate(range(0, len(plan), size))]


def _actions_of(item: str) -> list[str]:
    chunk = chunk_actions(item)
    return chunk if chunk is not None else [item]


def _on_plan_run(items: Sequence[str], plan: Sequence[str]) -> tuple[list[str], int]:
    """From the first item whose actions start the plan, the consecutive items that continue
    it; returns (kept items, number of plan actions they cover)."""
    for start in range(len(items)):
        kept: list[str] = []
        pos = 0
        for item in items[start:]:
            acts = _actions_of(item)
            if list(plan[pos:pos + len(acts)]) == acts:
                kept.append(item)
                pos += len(acts)
            else:
                break
        if kept:
            return kept, pos
    return [], 0


def recap_subtasks(hints: Mapping[str, Any], knobs: Knobs) -> list[str]:
    plan = list(hints.get("expert_plan") or [])
    purpose = str(hints.get("purpose", ""))
    depth = int(hints.get("depth", 0) or 0)
    if purpose == "task":
        return group_plan(plan, knobs.chunk_size)
    if purpose == "descend":
        task = str(hints.get("task", ""))
        acts = chunk_actions(task)
        if acts is None:
            return plan[:1]
        kept = []
        for a, p in zip(acts, plan):
            if a != p:
                break
            kept.append(a)
        return kept
    if purpose == "depth_cap":
        return plan[:1]
    if not plan:
        return []
    kept, covered = _on_plan_run(list(hints.get("remaining") or []), plan)
    if depth == 0 and covered < len(plan):
        start = len(kept) + 1
        extra = group_plan(plan[covered:], knobs.chunk_size)
        kept += [chunk_name(start + i, _actions_of(c)) for i, c in enumerate(extra)]
    return kept


def _next_action(hints: Mapping[str, Any]) -> str:
    plan = list(hints.get("expert_plan") or [])
    if plan:
        return plan[0]
    valid = hints.get("valid_actions")
    return valid[0] if valid else FALLBACK_ACTION


def expert_reply(hints: Mapping[str, Any], knobs: Knobs, call_key: str) -> dict[str, Any]:
    """The reply object (before JSON encoding) for one call, invalid-action injection applied."""
    style = str(hints.get("style", "recap"))
    purpose = str(hints.get("purpose", ""))
    plan = list(hints.get("expert_plan") or [])
    inject = knobs.invalid_action_rate > 0 and draw(call_key, knobs.seed, "invalid") < knobs.invalid_action_rate
    think = f"Expert plan: {len(plan)} action(s) left."
    if style == "recap" or (style == "adapt" and "plan" in purpose):
        subtasks = recap_subtasks(hints, knobs)
        if inject and subtasks:
            subtasks = [INVALID_ACTION] + subtasks[1:]
        reply: dict[str, Any] = {"think": think, "subtasks": subtasks}
        if hints.get("think") is False:
            del reply["think"]
        return reply
    if style in ("react", "act", "adapt"):
        action = INVALID_ACTION if inject else _next_action(hints)
        return {"action": action} if style == "act" else {"think": think, "action": action}
    if style in ("cot", "standard"):
        actions = plan[:] if plan else [_next_action(hints)]
        if inject:
            actions[0] = INVALID_ACTION
        return {"actions": actions} if style == "standard" else {"think": think, "actions": actions}
    raise ValueError(f"offline/expert: unknown style {style!r}")
