"""TEST DOUBLE ``offline/expert``: replies that follow the environment's expert plan.

Why: it drives every agent (ReCAP and the flat baselines) to success through the real agent
code, prompts and records, without a model - the end-to-end check of the pipeline. It reads
only the hints the agent and the episode worker attach (see recap/runtime.py), never the prompt,
and never the method's name:

- ``reply_fields``: the reply's fields, in order, as the agent class declares them
  (``think``, ``subtasks``, ``action``, ``actions``);
- ``purpose``: which prompt this is (``task``, ``descend``, refine kinds, ``depth_cap`` ...);
- ``task``, ``depth``, ``remaining`` (the node's current list), ``valid_actions``;
- ``expert_plan``: the remaining expert actions from the current environment state;
- ``text_layout`` (plain-text agents): the provider writes the reply in that layout
  (:func:`recap.baselines.textreply.render`) instead of JSON;
- ``finish_action`` and ``run_actions`` (the released ADaPT's executors): ``action`` is the
  finish word once the run has taken exactly the actions its task (a chunk) names.

``subtasks`` (the call order of recap/recap_agent.py):
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
#: action used for ``action`` / ``actions`` fields when the plan is empty and no valid actions are known
FALLBACK_ACTION = "look"
#: the reply fields the offline models fill (agents declare theirs: ``recap.agent.Agent.reply_fields``)
FIELDS = ("think", "subtasks", "action", "actions")
#: what a request that names no reply fields gets
DEFAULT_REPLY_FIELDS = ("think", "subtasks")


def chunk_name(index: int, actions: Sequence[str]) -> str:
    """The name of root chunk ``index``: the action itself for a one-action chunk (so ReCAP takes
    its shortcut), else ``subgoal <index>: a; b; ...``, which :func:`chunk_actions` parses back."""
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
    return [chunk_name(k + 1, plan[i : i + size]) for k, i in enumerate(range(0, len(plan), size))]


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
            if list(plan[pos : pos + len(acts)]) == acts:
                kept.append(item)
                pos += len(acts)
            else:
                break
        if kept:
            return kept, pos
    return [], 0


def recap_subtasks(hints: Mapping[str, Any], knobs: Knobs) -> list[str]:
    """The ``subtasks`` offline/expert gives a ReCAP call with these hints, following the expert
    plan (the rule per purpose is in the module docstring)."""
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


def _finish(hints: Mapping[str, Any]) -> str | None:
    """The word that ends an executor run (``hints["finish_action"]``, the released ADaPT's
    executors), once the run has taken every action its task names (``hints["run_actions"]``):
    a chunk's actions, or the one action a one-action chunk is named by. None otherwise."""
    finish = hints.get("finish_action")
    if not finish:
        return None
    task = str(hints.get("task", ""))
    wanted = chunk_actions(task) or [task]
    done = list(hints.get("run_actions") or [])
    return str(finish) if done == wanted else None


def reply_fields_of(hints: Mapping[str, Any]) -> tuple[str, ...]:
    """The reply's fields the agent asked for (``hints["reply_fields"]``, declared by each agent
    class); a request that names none gets a decomposition, as requests always did."""
    fields = hints.get("reply_fields")
    return tuple(str(f) for f in fields) if fields else DEFAULT_REPLY_FIELDS


def expert_reply(hints: Mapping[str, Any], knobs: Knobs, call_key: str) -> dict[str, Any]:
    """The reply object (before JSON encoding) for one call, invalid-action injection applied.

    Each field the agent asked for is filled the same way whatever the method: ``think`` says
    how much plan is left, ``subtasks`` follows the ReCAP call order above, ``action`` is the
    next expert action, ``actions`` the whole remaining plan. Injection replaces the first
    subtask, the action, or the plan's first action."""
    plan = list(hints.get("expert_plan") or [])
    inject = knobs.invalid_action_rate > 0 and draw(call_key, knobs.noise_seed, "invalid") < knobs.invalid_action_rate
    reply: dict[str, Any] = {}
    for name in reply_fields_of(hints):
        if name == "think":
            reply[name] = f"Expert plan: {len(plan)} action(s) left."
        elif name == "subtasks":
            subtasks = recap_subtasks(hints, knobs)
            if inject and subtasks:
                subtasks = [INVALID_ACTION] + subtasks[1:]
            reply[name] = subtasks
        elif name == "action":
            reply[name] = INVALID_ACTION if inject else (_finish(hints) or _next_action(hints))
        elif name == "actions":
            actions = plan[:] if plan else [_next_action(hints)]
            if inject:
                actions[0] = INVALID_ACTION
            reply[name] = actions
        else:
            raise ValueError(f"offline/expert: cannot fill reply field {name!r}; it fills {', '.join(FIELDS)}")
    return reply
