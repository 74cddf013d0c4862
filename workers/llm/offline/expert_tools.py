"""TEST DOUBLE ``offline/expert`` on coding environments: the gold patch's play, as tool calls or as
one bash command per turn.

The expert plan of a coding environment (``hints["expert_plan"]``, attached by the episode worker
from ``Environment.expert_plan()``) is a list of JSON tool calls ``{"name", "arguments"}``: the
rest of the gold patch's play from the current state, ending with ``submit`` twice (review, then
final). Two ways to answer:

* **tool calls** (:func:`tool_reply`; the request offers tools: ReCAP's tool-call mode,
  recap/recap_tools.py). The tree it makes the agent walk: the root lists the remaining work as
  consecutive groups named by what they do (``inspect the code`` for ``view``, ``change the
  code`` for ``str_replace``/``create``, ``run commands`` for ``bash``); a group's node calls
  the plan's next tool while the next call is of its kind (one call per reply, no text, id
  ``call_<call index>``) and then replies with an empty list; the root then lists what is left,
  and an empty list once only the submits are; the pre-root ("review and submit") lists
  ``submit``, and the ``submit`` node calls ``submit`` while the plan's next call is one (the
  review, then the final submit). So the agent descends, acts, returns, re-plans and submits
  twice, through its real prompts and records.
* **one bash command per turn** (:func:`bash_plan` + :func:`render_bash_block`; the text layout
  ``bash_block``: ReAct as mini-SWE-agent runs it, recap/baselines/react_swe.py): each call's
  bash equivalent (``view`` -> ``cat -n``, ``str_replace`` -> a ``python3`` edit script,
  ``create`` -> a ``python3`` write script), and the first ``submit`` -> the submit sentinel
  (text mode submits at once, without a review).

It reads only hints and the offered tools' names, never the prompt or the method's name.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

#: the text layout of mini-SWE-agent's replies (a THOUGHT, then one ```bash block)
BASH_BLOCK = "bash_block"
#: mini-SWE-agent's submit line (the command whose output starts with it submits)
SUBMIT_SENTINEL = "COMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT"
SUBMIT = "submit"
#: the pre-root's task and its one subtask (recap/recap_tool_prompts.py; kept as literals so the
#: test double does not import the agent)
PRE_ROOT_SUBTASK = "submit"
#: group names by tool
GROUPS = {"view": "inspect the code", "str_replace": "change the code", "create": "change the code", "bash": "run commands"}
_CALL_INDEX = re.compile(r"#(\d+)$")


@dataclass(frozen=True)
class ToolAnswer:
    """A reply of the expert in tool-call mode: its JSON text (may be empty) and its tool calls
    as ``{"id", "name", "arguments"}`` (``arguments`` the JSON string)."""

    text: str
    tool_calls: tuple[dict[str, str], ...] = ()


def plan_calls(hints: Mapping[str, Any]) -> list[dict[str, Any]]:
    """The expert plan's tool calls (items that are not JSON tool calls are left out)."""
    out = []
    for item in hints.get("expert_plan") or []:
        try:
            call = json.loads(item) if isinstance(item, str) else item
        except ValueError:
            continue
        if isinstance(call, dict) and isinstance(call.get("name"), str):
            out.append({"name": call["name"], "arguments": dict(call.get("arguments") or {})})
    return out


def group_of(call: Mapping[str, Any]) -> str:
    """The name of the group a call belongs to (``use <tool>`` for a tool without one)."""
    name = str(call["name"])
    return GROUPS.get(name, f"use {name}")


def work_groups(work: Sequence[Mapping[str, Any]]) -> list[str]:
    """The work's consecutive runs of one group, as the group names (the root's subtasks)."""
    out: list[str] = []
    for call in work:
        g = group_of(call)
        if not out or out[-1] != g:
            out.append(g)
    return out


def _call_id(call_key: str) -> str:
    m = _CALL_INDEX.search(call_key)
    return f"call_{m.group(1) if m else 0}"


def _plan_reply(think: str, subtasks: Sequence[str]) -> ToolAnswer:
    return ToolAnswer(json.dumps({"think": think, "subtasks": list(subtasks)}))


def _call(call: Mapping[str, Any], call_key: str) -> ToolAnswer:
    return ToolAnswer("", ({"id": _call_id(call_key), "name": str(call["name"]), "arguments": json.dumps(call["arguments"])},))


def tool_reply(hints: Mapping[str, Any], call_key: str) -> ToolAnswer:
    """The expert's answer to a ReCAP tool-mode request (the rules are in the module docstring).
    Hints read: ``task``, ``is_root``, ``is_pre_root``, ``expert_plan``."""
    plan = plan_calls(hints)
    submits = next((i for i, c in enumerate(plan) if c["name"] == SUBMIT), len(plan))
    work = plan[:submits]
    task = str(hints.get("task", ""))
    if hints.get("is_pre_root"):
        return _plan_reply("The change is made; review and submit it.", [PRE_ROOT_SUBTASK] if plan else [])
    if hints.get("is_root"):
        return _plan_reply(f"Expert plan: {len(work)} call(s) before submitting.", work_groups(work))
    if task == PRE_ROOT_SUBTASK and not work and plan:
        return _call(plan[0], call_key)
    if work and (task == group_of(work[0]) or task not in GROUPS.values()):
        return _call(work[0], call_key)
    return _plan_reply(f"Nothing left for {task!r}.", [])


def bash_command(call: Mapping[str, Any], sentinel: str = SUBMIT_SENTINEL) -> str:
    """One tool call as one bash command (the text-mode equivalent)."""
    name, args = str(call["name"]), call.get("arguments") or {}
    if name == "bash":
        return str(args.get("command", ""))
    if name == "view":
        view_range = args.get("view_range")
        if isinstance(view_range, list) and len(view_range) == 2:
            start, end = int(view_range[0]), int(view_range[1])
            return f"sed -n '{start},{'$' if end < 0 else end}p' {json.dumps(str(args['path']))}"
        return f"cat -n {json.dumps(str(args['path']))}"
    if name == "str_replace":
        return _python_script(
            f"p = pathlib.Path({json.dumps(str(args['path']))})",
            f"old = {json.dumps(str(args['old_str']))}",
            f"new = {json.dumps(str(args.get('new_str', '')))}",
            "text = p.read_text()",
            'assert text.count(old) == 1, "the text to replace does not occur exactly once"',
            "p.write_text(text.replace(old, new, 1))",
        )
    if name == "create":
        return _python_script(
            f"p = pathlib.Path({json.dumps(str(args['path']))})",
            "p.parent.mkdir(parents=True, exist_ok=True)",
            f"p.write_text({json.dumps(str(args['file_text']))})",
        )
    if name == SUBMIT:
        return f"echo {sentinel}"
    raise ValueError(f"offline/expert: no bash equivalent of the tool {name!r}")


def _python_script(*lines: str) -> str:
    """A ``python3`` heredoc (quoted delimiter: the shell expands nothing; JSON string literals
    are valid Python string literals, so any text survives)."""
    return "python3 - <<'EOF'\nimport pathlib\n" + "\n".join(lines) + "\nEOF"


def bash_plan(hints: Mapping[str, Any]) -> list[str]:
    """The plan as bash commands, up to and including the first submit (as the sentinel: the
    hints' ``submit_sentinel`` where the agent's configuration prints another, mini-swe-agent 1.0.0's)."""
    out = []
    sentinel = str(hints.get("submit_sentinel") or SUBMIT_SENTINEL)
    for call in plan_calls(hints):
        out.append(bash_command(call, sentinel))
        if call["name"] == SUBMIT:
            break
    return out


def render_bash_block(reply: Mapping[str, Any]) -> str:
    """A reply in mini-SWE-agent's layout: a THOUGHT paragraph, then one ```bash block."""
    think = reply.get("think") or "The next step of the plan."
    return f"THOUGHT: {think}\n\n```bash\n{reply.get('action') or ''}\n```"
