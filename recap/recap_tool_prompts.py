"""ReCAP's prompts in tool-call mode (coding environments), in our own words.

What each prompt carries follows the paper's "Tool Call Prioritized Prompt for SWE-bench"
appendix and the release's templates (swebench-recap/config/recap.yaml:28-55): the *action
taken* prompt shows the latest observation, the current task and the subtasks proposed before;
the *down* prompt names the child's task; the *up* prompt names the finished task, the parent's
task, the parent's latest think and its remaining subtasks (the structured re-injection). Each
ends with the same four choices: refine the list, reply with an empty list when the current task
is done, break the first subtask down further by replying without a tool call, and/or call tools.
The sentences are ours.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from recap.recap_prompts import numbered

#: the task of the node above the root (swebench-recap/sweagent/agent/agents.py:618)
PRE_ROOT_TASK = "review and submit"
#: the pre-root's one subtask (agents.py:619)
SUBMIT_SUBTASK = "submit"


def reply_format(with_think: bool) -> str:
    """The JSON text of every reply (tool calls go beside it, not inside it)."""
    if with_think:
        return '{"think": "<your reasoning>", "subtasks": ["<subtask>", ...]}'
    return '{"subtasks": ["<subtask>", ...]}'


def reply_schema(with_think: bool) -> dict[str, Any]:
    """The reply text's JSON schema for strict structured output (``reply_schema``), as the
    release asks for its replies (swebench-recap/sweagent/agent/models.py:707-731: an object of
    a string ``think`` and a list of strings ``subtasks``, both required, nothing else); the
    descriptions are ours. Without a think (``no_think``) only ``subtasks``."""
    props: dict[str, Any] = {}
    if with_think:
        props["think"] = {"type": "string", "description": "Your reasoning about the current task and the latest observation."}
    props["subtasks"] = {
        "type": "array",
        "items": {"type": "string"},
        "description": "The ordered subtasks still needed for the current task; empty when it is complete.",
    }
    return {
        "name": "ReCAP",
        "schema": {"type": "object", "properties": props, "required": list(props), "additionalProperties": False},
    }


def pre_root_think(issue: str) -> str:
    """The pre-root node's think: check that the issue is resolved, then submit (agents.py:619
    puts the problem statement after such a sentence)."""
    return f"Check that the following issue is really resolved, then submit the change:\n{issue}"


def system_text(with_think: bool) -> str:
    """How ReCAP works with tools: a subtask list per task, the head carried out next; tools
    are called to act and take priority over breaking a task down; the reply's JSON format."""
    think_line = '- "think": your reasoning about the current task and the latest observation.\n' if with_think else ""
    return (
        "You solve a task by planning recursively and acting through tool calls. For the task you "
        "are working on, you keep an ordered list of subtasks. The first subtask is worked on next: "
        "reply without a tool call and it becomes your current task, to be broken down or acted "
        "on. To act, call a tool; its result comes back to you together with your current task and "
        "your list, which you then revise. When a task is finished, reply with an empty list and "
        "you return to the task above it, where I show you its reasoning and the subtasks still "
        "ahead. Acting takes priority: when a tool call makes progress, make it.\n\n"
        "Every reply holds one JSON object as its text (tool calls may go with it):\n"
        f"{reply_format(with_think)}\n"
        f"{think_line}"
        '- "subtasks": the ordered subtasks still needed for the current task; an empty list when '
        "the current task is complete. Do not list anything outside the current task."
    )


def task_prompt(*, rules: str, observation: str, goal: str, with_think: bool) -> str:
    """The pinned first prompt: the system text, the environment's rules, the first observation
    (the issue) and the goal, asking to start (no demonstration: the paper's SWE-bench protocol)."""
    return "\n\n".join(
        [
            system_text(with_think),
            f"The environment:\n{rules}",
            f"The issue:\n{observation}",
            f"Your current task: {goal}",
            "Begin: write the subtasks of this task, and/or call tools.",
        ]
    )


#: how the prompts after a reply end (the paper's four choices, in our words)
_CHOICES = (
    "Now you may revise the subtasks in light of the latest observation, reply with an empty list "
    "if your current task is complete, break the first subtask down further by replying without a "
    "tool call, and/or call tools to make progress."
)
_CHOICES_DOWN = (
    "Now you may break this task down if it is too large, reply with an empty list if it is "
    "already complete, go further down into its first subtask by replying without a tool call, "
    "and/or call tools to make progress."
)


def action_taken_prompt(*, observation: str, task: str, subtasks: Sequence[str]) -> str:
    """After a tool call: the latest observation, the current task and the list proposed before
    (recap.yaml:28-37); it is the content of the call's tool message, as in the release
    (agents.py:750-753)."""
    return (
        f"Latest observation:\n{observation}\n\nYour current task: {task}\n\n"
        f"The subtasks you proposed before:\n{numbered(subtasks)}\n\n{_CHOICES}"
    )


def down_prompt(task: str) -> str:
    """On entering a child node (recap.yaml:38-43)."""
    return f"OK.\n\nYour current task: {task}\n\n{_CHOICES_DOWN}"


def depth_cap_prompt(task: str) -> str:
    """At ``max_level``: the task may not be broken down; act on it or say it is done."""
    return (
        f"OK.\n\nYour current task: {task}\n\n"
        "This task may not be broken down any further. Call tools to carry it out, or reply with "
        "an empty list if it is already complete."
    )


def _thought(thinks: Sequence[str], mode: str) -> str | None:
    if mode == "none" or not thinks:
        return None
    if mode == "many":
        return "Your earlier reasoning for it, oldest first:\n" + numbered(thinks)
    return f"Your latest reasoning for it: {thinks[-1]}"


def up_prompt(
    *, done_task: str, task: str, thinks: Sequence[str], subtasks: Sequence[str], think_mode: str, name_only: bool
) -> str:
    """Back at the parent (recap.yaml:44-55): the finished task, the parent's task, its latest
    think (``think_mode``: latest | many | none) and remaining subtasks (left out under
    ``name_only``)."""
    parts = [
        f"You judged the task {done_task!r} to be complete.",
        f"You are back at the task above it.\nYour current task: {task}",
    ]
    if not name_only:
        thought = _thought(thinks, think_mode)
        if thought:
            parts.append(thought)
        parts.append("Its remaining subtasks:\n" + numbered(subtasks))
    parts.append(_CHOICES)
    return "\n\n".join(parts)


def one_call_prompt(n_calls: int) -> str:
    """The re-ask after a reply that made several tool calls where one is allowed (the release's
    format-error requery for ``multiple`` calls, swebench-recap/sweagent/tools/parsing.py:384-385,
    439-449): none of them was run; make exactly one call per reply, the JSON text beside it."""
    return (
        f"Your last reply made {n_calls} tool calls, and none of them was run: make exactly one tool call "
        "per reply, with your JSON object as the reply's text. Reply again with your first call only."
    )
