"""Prompt templates of the baselines, in our own words.

Each template carries the information of the benchmark's original baseline prompt (Robotouille's
ReAct and I/O / I/O-CoT prompts, ADaPT's executor and planner prompts): what the agent is, the
reply format, what each field must hold, the environment rules, the observation and the goal,
and error feedback after an action that is not valid. The sentences are ours; replies are JSON
objects, as for ReCAP, so every agent parses and repairs replies the same way.

``preamble=False`` (demonstration rendering) leaves out the system text and the rules: the
demonstration shows only what changes from one episode to the next.
"""

from __future__ import annotations

from collections.abc import Sequence

# -- reply formats (also shown to the model in repair messages) ---------------------------------


def action_format(with_think: bool) -> str:
    """ReAct (with think) and Act (without)."""
    if with_think:
        return '{"think": "<your reasoning>", "action": "<one valid action>"}'
    return '{"action": "<one valid action>"}'


def plan_format(with_think: bool) -> str:
    """CoT (with think) and Standard (without)."""
    if with_think:
        return '{"think": "<your reasoning>", "actions": ["<action>", ...]}'
    return '{"actions": ["<action>", ...]}'


EXECUTOR_FORMAT = (
    '{"think": "<your reasoning>", "action": "<one valid action>"} to act, or '
    '{"think": "<your reasoning>", "status": "done" or "failed"} to finish the task'
)

PLANNER_FORMAT = '{"think": "<your reasoning>", "subtasks": ["<subtask>", ...], "logic": "and" or "or"}'


# -- system texts ---------------------------------------------------------------------------------


def action_system_text(with_think: bool) -> str:
    """The system text of ReAct (``with_think``) or Act, at the head of the pinned task prompt: one
    action per turn, invalid actions are not carried out, the reply format and what each field
    holds."""
    think_line = (
        '- "think": your reasoning before acting: what the goal still needs, what the latest '
        "observation and your earlier steps tell you, and why the action you choose moves you "
        "towards the goal. If your last action was rejected, first work out why it was not valid.\n"
        if with_think
        else ""
    )
    how = "think about the latest observation, then choose" if with_think else "choose"
    return (
        "You are an agent that reaches a goal in an environment one action at a time. At every "
        f"turn you {how} exactly one action; I carry it out and show you what happened. An "
        "action that is not one of the valid actions is not carried out, and I tell you so.\n\n"
        "Answer every time with one JSON object and nothing else:\n"
        f"{action_format(with_think)}\n"
        f"{think_line}"
        '- "action": the single next action, written exactly as it appears among the valid actions.'
    )


def plan_system_text(with_think: bool) -> str:
    """The system text of CoT (``with_think``) or Standard, at the head of their one prompt: write
    the complete plan at once, since it runs without asking again; the reply format and what each
    field holds."""
    think_line = (
        '- "think": your reasoning: what the goal requires, which steps get there, and how each '
        "action changes the state that the following actions start from.\n"
        if with_think
        else ""
    )
    return (
        "You are an agent that reaches a goal in an environment. You see the starting state "
        "once and write the complete plan: every action, in order, that takes the environment "
        "from this state to the goal. The actions are then carried out one after another without "
        "asking you again, so the plan must allow for the way each action changes the state.\n\n"
        "Answer with one JSON object and nothing else:\n"
        f"{plan_format(with_think)}\n"
        f"{think_line}"
        '- "actions": the whole plan, one action per item, each written exactly as the '
        "environment's actions are written (no numbering, no comments)."
    )


def executor_system_text() -> str:
    """The system text of an ADaPT executor run, at the head of its pinned task prompt: carry out
    one task action by action and stop with a done or failed status; the reply forms and what each
    field holds."""
    return (
        "You are the executor of a planning system: you carry out one task in an environment, one "
        "action at a time. After each action I show you what happened. An action that is not one "
        "of the valid actions is not carried out, and I tell you so. You see only your own task; "
        "it may be one part of a larger goal, so do what the task asks and then stop.\n\n"
        "Answer every time with one JSON object and nothing else, in one of these forms:\n"
        '{"think": "<your reasoning>", "action": "<one valid action>"} to take the next action;\n'
        '{"think": "<your reasoning>", "status": "done"} once the task is finished, or\n'
        '{"think": "<your reasoning>", "status": "failed"} if, after trying your best, you '
        "conclude that the task cannot be carried out.\n"
        '- "think": your reasoning about the task, the latest observation and your next move.\n'
        '- "action": written exactly as it appears among the valid actions.\n'
        '- "status": only when you stop working on the task; never together with an action.'
    )


def planner_system_text() -> str:
    """The system text of an ADaPT planner call: break a task the executor could not do into
    self-contained subtasks combined by ``and``/``or`` logic; the reply format and what each field
    holds."""
    return (
        "You are the planner of a planning system. An executor tried to carry out a task in an "
        "environment and did not manage it on its own. Break the task into a short list of "
        "simpler subtasks (usually two to four). Each subtask goes to an executor that sees only "
        "that subtask and the environment, not the task above it nor the other subtasks, so every "
        "subtask must make sense by itself and name the objects it concerns. A subtask that is "
        "still too hard is broken down again in the same way.\n\n"
        "Answer with one JSON object and nothing else:\n"
        f"{PLANNER_FORMAT}\n"
        '- "think": your reasoning about what the task needs, given the current observation.\n'
        '- "subtasks": the subtasks, in the order they should be attempted.\n'
        '- "logic": "and" when every subtask must succeed (they run in order and the task fails '
        'at the first one that fails); "or" when the subtasks are alternatives (they are tried in '
        "order until one succeeds)."
    )


# -- task prompts ---------------------------------------------------------------------------------


def _with_preamble(system: str, rules: str, body: list[str], preamble: bool) -> str:
    parts = [system, f"Rules of the environment:\n{rules}"] if preamble else []
    return "\n\n".join([*parts, *body])


def thought_line(with_think: bool) -> str:
    """How ReAct (``with_think``) or Act thinks without acting, when thoughts are answered "OK."
    (``think_actions``; the released ALFWorld ReAct and Act, whose examples think this way)."""
    if with_think:
        return 'To think without acting, write the action as "think: <your thought>"; I answer "OK." and no step is used.'
    return 'To think without acting, reply {"think": "<your thought>"} with no "action"; I answer "OK." and no step is used.'


def action_task_prompt(
    *, rules: str, observation: str, goal: str, with_think: bool, preamble: bool, think_actions: bool = False
) -> str:
    """The pinned task prompt of ReAct / Act (``think_actions``: the system text says how to think
    without acting)."""
    body = [f"Initial observation:\n{observation}", f"Your goal:\n{goal}", "Reply with your first action."]
    system = action_system_text(with_think)
    if think_actions:
        system = f"{system}\n{thought_line(with_think)}"
    return _with_preamble(system, rules, body, preamble)


def plan_task_prompt(*, rules: str, observation: str, goal: str, with_think: bool, preamble: bool) -> str:
    """The pinned (and only) prompt of CoT / Standard."""
    body = [f"Initial observation:\n{observation}", f"Your goal:\n{goal}", "Reply with your complete plan."]
    return _with_preamble(plan_system_text(with_think), rules, body, preamble)


def _situation(observation: str, last_action: str | None, initial_observation: str | None) -> list[str]:
    parts = []
    if initial_observation is not None:
        parts.append(f"Observation at the start of the episode:\n{initial_observation}")
    if last_action is not None:
        parts.append(f"Last action taken in the environment: {last_action}")
    parts.append(f"Current observation:\n{observation}")
    return parts


def executor_task_prompt(
    *,
    rules: str,
    task: str,
    observation: str,
    last_action: str | None,
    initial_observation: str | None,
    preamble: bool,
) -> str:
    """The pinned task prompt of one ADaPT executor run."""
    body = [
        *_situation(observation, last_action, initial_observation),
        f"Your task: {task}",
        "Reply with your first action, or with a status if the task needs no action.",
    ]
    return _with_preamble(executor_system_text(), rules, body, preamble)


def planner_task_prompt(
    *,
    rules: str,
    task: str,
    observation: str,
    last_action: str | None,
    initial_observation: str | None,
    preamble: bool,
) -> str:
    """The pinned prompt of one ADaPT planner call."""
    body = [
        *_situation(observation, last_action, initial_observation),
        f"Task to break down: {task}",
        "Write the subtasks and how they combine.",
    ]
    return _with_preamble(planner_system_text(), rules, body, preamble)


# -- feedback during an episode ------------------------------------------------------------------


def observation_prompt(observation: str) -> str:
    """The user message after an action that reached the environment (ReAct, Act, ADaPT executor):
    the new observation."""
    return f"Observation:\n{observation}"


def invalid_action_prompt(action: str, observation: str) -> str:
    """Error feedback after an action that never reached the environment (``reject`` mode)."""
    return (
        f"Error feedback: '{action}' is not one of the valid actions, so it was not carried out "
        "and nothing changed. Choose an action exactly as it is written among the valid actions.\n\n"
        f"Observation:\n{observation}"
    )


#: the answer to a thought (``think_actions``), as in the released ALFWorld ReAct and Act
THOUGHT_ACK = "OK."


def explained_invalid_prompt(action: str, observation: str, valid_actions: Sequence[str] | None, *, with_think: bool) -> str:
    """Feedback after a command that reached the game but is not a valid action (ALFWorld under
    the profiles): what happened, three numbered likely causes, then the game's answer and, when
    that answer does not already list them, the valid actions. Our words; it carries what the
    released feedback carries (alfworld-recap/react_alfworld/react.py:161-170): the command is not
    among the valid actions, assumptions may be wrong, inexact wording, a thought not marked as
    one, and the list."""
    thought = (
        'write the action as "think: <your thought>"' if with_think else 'reply {"think": "<your thought>"} with no "action"'
    )
    lines = [
        f"'{action}' is not one of the valid actions, so it changed nothing. Likely causes:",
        "1. The command is not an exact copy of a valid action: copy it word for word, numbers included.",
        f"2. You meant to think rather than act: to think, {thought}.",
        "3. Something you assumed about the situation does not hold: check the latest observation.",
        "",
        f"Observation:\n{observation}",
    ]
    if valid_actions is not None:
        lines += ["", "Valid actions:", *valid_actions]
    return "\n".join(lines)


def planner_transcript(
    prompt: str, reply: str, header: str = "Here is an example of a task being broken down into subtasks."
) -> str:
    """The planner's demonstration: one example prompt and its decomposition (``header`` opens it)."""
    return "\n\n".join(
        [
            header,
            f"[Example prompt]\n{prompt}",
            f"[Example reply]\n{reply}",
            "[End of example.]",
        ]
    )
