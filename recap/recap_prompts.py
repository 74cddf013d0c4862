"""ReCAP's prompt templates, in our own words.

Each function carries the information the paper's template carries (Appendix "Core Framework
Prompts"); the sentences are ours. The ablation switches change only what is re-injected:
``think`` = latest | none | many, ``name_only`` = only the finished and the current task.
"""

from __future__ import annotations

import json
from collections.abc import Sequence


def reply_format(with_think: bool) -> str:
    """The JSON reply every ReCAP call asks for: the (refined) subtask list, after the thought
    unless ``think`` is off. Shown in the system text and in JSON repair messages."""
    if with_think:
        return '{"think": "<your reasoning>", "subtasks": ["<subtask>", ...]}'
    return '{"subtasks": ["<subtask>", ...]}'


def system_text(with_think: bool) -> str:
    """ReCAP's system text, at the head of the pinned task prompt: how recursive planning works (a
    subtask list per task, its head carried out next, the list revised on return), the reply format
    and what each field must hold."""
    think_line = '- "think": your reasoning about the current task and the latest observation.\n' if with_think else ""
    return (
        "You are an agent that reaches a goal in an environment by planning recursively. "
        "For the task you are currently working on, you write an ordered list of subtasks; "
        "the first subtask is carried out next (broken down further if it is not a single "
        "action), and afterwards you come back to the task to revise the rest of the list "
        "using what was observed. I keep track of the plan for you: whenever you return to a "
        "task I show you its previous reasoning and the subtasks still ahead.\n\n"
        "Answer every time with one JSON object and nothing else:\n"
        f"{reply_format(with_think)}\n"
        f"{think_line}"
        '- "subtasks": the updated, ordered list of subtasks for the current task. When the '
        "current task can be done with a single action from the valid actions, the list holds "
        "exactly that action, written exactly as it appears. When the current task is already "
        "complete, the list is empty."
    )


def numbered(items: Sequence[str]) -> str:
    """Items as ``1. item`` lines, ``(none)`` when empty: how return prompts show the remaining
    subtasks and earlier thoughts."""
    return "\n".join(f"{i}. {s}" for i, s in enumerate(items, 1)) if items else "(none)"


def task_prompt(*, rules: str, observation: str, goal: str, with_think: bool, preamble: bool) -> str:
    """The pinned task prompt, ReCAP's first call (the root decomposition): the system text and
    rules (left out when rendering a demonstration, ``preamble=False``), the initial observation and
    the goal, asking for high-level subtasks."""
    parts = []
    if preamble:
        parts += [system_text(with_think), f"Rules of the environment:\n{rules}"]
    parts += [
        f"Initial observation:\n{observation}",
        f"Your goal:\n{goal}",
        "Begin the task: first write a list of high-level subtasks that together reach the goal.",
    ]
    return "\n\n".join(parts)


def release_task_prompt(*, system: str, rules: str, observation: str, goal: str, ask_many: bool) -> str:
    """ReCAP's first prompt under ``prompts: release`` on Robotouille: the released template's
    system text and rules (``ReleasePrompt.system``/``rules``), the first observation and the
    goal, in the layout of ``robotouille-recap/MATRIX/MATRIX/chatbot.py:247-261`` (a leading
    newline, the system text, a whitespace-only line, the rules under a heading, the observation,
    the goal under a sentence of its own, a closing request and a trailing newline). The framing
    sentences are ours. ``ask_many``: the main code's closing also asks for more than one subtask
    and its spacer line holds eight spaces; the ablations' code (``chatbot_no_think.py:238-252``,
    ``chatbot_name_only.py:238-252``, ``chatbot_think_many.py``, ``chatbot_level_<n>.py``) has neither."""
    spacer, close = ("        ", " Remember to write more than a single subtask.") if ask_many else ("", "")
    return (
        f"\n{system}\n{spacer}\nThe environment's rules:\n{rules}\n\n{observation}\n\n"
        f"You are to prepare a new meal. The goal is described as follows:\n{goal}\n\n"
        f"Begin the task now.{close}\n"
    )


def release_alfworld_task_prompt(*, system: str, rules: str, observation: str, goal: str) -> str:
    """ReCAP's first prompt under ``prompts: release`` on ALFWorld, in the layout of
    ``alfworld-recap/MATRIX/MATRIX/chatbot.py:242-253`` (the same in every ``chatbot_*.py``): a
    leading newline, the system text (empty as released, SessionManager.py:83-84), a blank line,
    the rule under a heading, the first observation with its valid actions (main.py:76), then the
    task on a line of its own (the goal the observation states, SessionManager.py:86) and a
    trailing newline. The framing sentences are ours."""
    return f"\n{system}\n\nThe environment's rule:\n{rules}\n\n{observation}\n\nThe task at hand: {goal}\n"


def release_reminder(rules: str) -> str:
    """The released rules reminder (``robotouille-recap/MATRIX/MATRIX/chatbot.py:431-439``), put
    before the prompt it rides on: a sentence, a blank line, the rules, a blank line, an end
    marker and a blank line. The sentences are ours."""
    return f"Many turns have passed, so here are the operating rules again, lest they slip your mind:\n\n{rules}\n\nRULES END\n\n"


def descend_prompt(task: str) -> str:
    """The prompt of a descend call, on entering a child node: names the child's task and asks for
    its own subtask list."""
    return f"OK.\n\nYour current task: {task}\n\nWrite the list of subtasks for this task."


def depth_cap_prompt(task: str) -> str:
    """The prompt of a descend call at ``max_level`` (kind ``depth_cap``): names the task and asks
    for exactly one valid action instead of a decomposition."""
    return (
        f"OK.\n\nYour current task: {task}\n\n"
        "This task may not be broken down any further. Reply with a list holding exactly one "
        "action, copied exactly from the valid actions, that carries out this task."
    )


def _thinks(thinks: Sequence[str], mode: str) -> str | None:
    if mode == "none" or not thinks:
        return None
    if mode == "many":
        return "Your earlier reasoning for this task, oldest first:\n" + numbered(thinks)
    return f"Your reasoning so far: {thinks[-1]}"


def return_prompt(
    *,
    outcome: str,
    child_task: str,
    parent_task: str,
    thinks: Sequence[str],
    subtasks: Sequence[str],
    observation: str | None,
    think_mode: str,
    name_only: bool,
    failed_action: str | None = None,
    hints: str = "",
) -> tuple[str, str]:
    """The prompt for returning to ``parent_task`` after ``child_task`` ended; (kind, text).

    ``outcome`` is ``leaf`` (an action ran), ``fail`` (the action was not valid; no step was
    taken) or ``nonleaf`` (a decomposed subtask finished). ``subtasks`` is the parent's list as
    shown: its remaining subtasks (the head removed) after success, the full list after a failure.
    """
    kind, lines = _child_outcome(outcome, child_task, bool(subtasks), observation, failed_action, hints)
    lines.append(f"You are back at the task above it.\nYour current task: {parent_task}")
    if not name_only:
        thought = _thinks(thinks, think_mode)
        if thought:
            lines.append(thought)
        if outcome == "fail" or subtasks:
            lines.append("Your remaining subtasks:\n" + numbered(subtasks))
    lines.append(_return_instruction(outcome, kind))
    return kind, "\n\n".join(lines)


def _child_outcome(
    outcome: str, child_task: str, has_rest: bool, observation: str | None, failed_action: str | None, hints: str
) -> tuple[str, list[str]]:
    """(kind, opening lines): how the child ended - failed, or done with its result - and which
    return prompt that makes (``leaf_fail``, ``leaf_done``/``leaf_judge``, ``nonleaf_done``/``nonleaf_judge``)."""
    lines: list[str] = []
    if outcome == "fail":
        lines.append(f"You could not complete the task: {child_task}")
        shown = f" ('{failed_action}')" if failed_action and failed_action != child_task else ""
        lines.append(f"The action{shown} is not one of the valid actions, so nothing was done.")
        if observation is not None:
            lines.append(f"Current observation:\n{observation}")
        if hints:
            lines.append(f"Common causes:\n{hints}")
        return "leaf_fail", lines
    lines.append(f"You have completed the task: {child_task}")
    if outcome == "leaf" and observation is not None:
        lines.append(f"Result:\n{observation}")
    elif outcome == "nonleaf":
        lines.append("Its results are in the conversation above.")
    if outcome == "leaf":
        return ("leaf_done" if has_rest else "leaf_judge"), lines
    return ("nonleaf_done" if has_rest else "nonleaf_judge"), lines


def _return_instruction(outcome: str, kind: str) -> str:
    """The closing instruction: fix the error, judge the finished task, or revise what remains."""
    if outcome == "fail":
        return "Change your list of subtasks so that the error is fixed."
    if kind in ("leaf_judge", "nonleaf_judge"):
        return (
            "No subtasks are left. Decide whether the current task is complete: if it is, reply "
            "with an empty list; if not, list the subtasks still needed."
        )
    return (
        "Revise the remaining subtasks in light of the latest observation so that the goal is "
        "reached. If none are needed any more, check whether the current task is complete and "
        "reply with an empty list if it is. Do not add subtasks outside the current task."
    )


def shortcut_reply(action: str, with_think: bool) -> str:
    """The synthetic reply the released code records for a shortcut (no model call)."""
    reply = {"think": "This task is itself one of the valid actions, so I carry it out directly.", "subtasks": [action]}
    if not with_think:
        del reply["think"]
    return json.dumps(reply)


def reminder(rules: str) -> str:
    """The rules again, prepended to whichever prompt is sent next when a reminder is due (every
    ``reminder_period`` calls or control-loop iterations)."""
    return f"Reminder of the environment rules:\n{rules}"


def final_answer_prompt() -> str:
    """The last call when the root's list has emptied (``final_answer``): the answer as a single
    action in the subtask list, short and concrete."""
    return (
        "The task list is finished. Give your final answer now as one action in your subtasks, "
        "as concrete as you can and without a long sentence."
    )


def bad_json_text() -> str:
    """The message after a reply that is not JSON (``resend_bad_replies``); the prompt follows again."""
    return "Your reply could not be read as JSON. Check its format."


def reply_error_text(error: str) -> str:
    """The message after a JSON reply that could not be used (``resend_bad_replies``); ``error``
    names what went wrong; the prompt follows again."""
    return f"Your reply could not be used ({error}). Try again."
