"""Prompts of the baselines under ``reply_format: text`` and of the released ADaPT, in our words.

Each carries what the released prompt carries (the file named in each docstring, in GitHub
``ReCAP-Stanford/ReCAP`` at 2fb112f): what the agent is, the reply layout
(:mod:`recap.baselines.textreply`), what each part holds, and that error feedback may come
first. No sentence of the release is copied. ``preamble=False`` (demonstration rendering) leaves
out the system text and the rules, as the JSON prompts do.
"""

from __future__ import annotations

from recap.baselines.prompts import planner_transcript


def _feedback_note() -> str:
    return (
        "A message may start with 'Error feedback:', about your previous reply that could not be "
        "used (it was not carried out); the observation after it is unchanged."
    )


def react_system(with_think: bool) -> str:
    """ReAct (``with_think``) / Act in the labelled layout (robotouille-baselines prompts
    ReAct/1.0.0-original.yml, Act/1.0.0-original.yml)."""
    lines = ["Reasoning: <your reasoning>", "Action: <one valid action>"] if with_think else ["Action: <one valid action>"]
    think = "Reason about the latest observation, then name" if with_think else "Name"
    return (
        "You are an agent working towards a goal in an environment, one action per turn. Each "
        "message shows the current observation (the objects, the goal and the valid actions). "
        f"{think} the single action that moves you closest to the goal.\n\n"
        f"{_feedback_note()}\n\n"
        "Reply in plain text, exactly in this layout:\n" + "\n".join(lines)
    )


def yao_system() -> str:
    """ReAct on ALFWorld in Yao et al.'s one-line layout (alfworld-recap/react_alfworld/react.py:132-142
    and its examples): each reply is one line, a thought or a command."""
    return (
        "You act in a household to complete a task. Each reply is a single line: either a thought "
        "that starts with 'think:' (I answer OK.), or one command for the game, written exactly as it "
        "appears among the valid actions. Only one item can be held at a time; check the inventory "
        "when unsure what you hold."
    )


def plan_system(with_think: bool) -> str:
    """CoT (``with_think``: I/O-CoT, prompts IO/1.1.0-io-cot.yml) and Standard (I/O,
    IO/1.0.0-io.yml): the whole plan in one reply."""
    if with_think:
        layout = (
            "Reply in plain text: one line per action, in order, each starting with 'Action: ', and after "
            "each action a line starting with 'Next state: ' that says what the action changes. Lines that "
            "do not start with 'Action: ' are not carried out."
        )
    else:
        layout = (
            "Reply in plain text: a line 'Plan:' followed by the actions, one per line, in order, with no "
            "numbers, bullets or other text."
        )
    return (
        "You are an agent that reaches a goal in an environment by writing the whole plan at once. You "
        "see the starting observation (the objects, the goal and the valid actions). Write every action "
        "exactly as the environment writes its actions. The plan is checked action by action before "
        "anything runs; if one action cannot be matched, none is carried out.\n\n" + layout
    )


def executor_system() -> str:
    """The released ADaPT executor (robotouille-baselines prompts Adapt/custom-executor.yml): a
    ReAct agent pursuing one subtask that each message names."""
    return (
        "You are an agent in an environment, working on one subtask of a larger goal. Each message "
        "shows the current observation and, after it, the subtask you are working on. Pursue only "
        "that subtask: reason briefly about how the observation and the environment's rules let you "
        "advance it, then name one low-level action that does.\n\n"
        f"{_feedback_note()}\n\n"
        "Reply in plain text, exactly in this layout:\nReasoning: <your reasoning>\nAction: <one valid action>"
    )


def planner_system() -> str:
    """The released ADaPT planner (robotouille-baselines prompts Adapt/planner_system.txt)."""
    return (
        "You are a planner. From the observation (the objects, the goal and the valid actions), split "
        "the goal into a short plan of two to four abstract subtasks for an executor that carries them "
        "out one by one. A subtask names the objects it concerns but is not itself one of the valid "
        "actions; do not repeat the observation.\n\n"
        "Reply in plain text: your reasoning, then one line per subtask in the form 'Step <n>: <subtask>', "
        "then one final line 'Execution order: <expression>' that combines the steps with AND, OR and "
        "parentheses, for example 'Execution order: (Step 1 AND Step 2) AND Step 3'."
    )


def task_prompt(*, system: str, rules: str, body: str, preamble: bool) -> str:
    """A pinned first prompt: system text and rules (left out when rendering a demonstration),
    then the first turn's message."""
    parts = [system, f"Rules of the environment:\n{rules}"] if preamble else []
    return "\n\n".join([*parts, body])


#: the one rule the released ALFWorld baselines state, written in their Python code
#: (alfworld-recap/react_alfworld/react.py:136-137, act_alfworld/act.py:162-163); ours in our words
RELEASE_ALFWORLD_RULE = (
    "You can hold only one item at a time. Check your inventory whenever you are unsure what you are "
    "holding or are about to pick something up."
)


#: the JSON reply the released ALFWorld Act's first prompt shows as an example (act.py:167); ours
RELEASE_JSON_EXAMPLE = '{"action": "open the drawer"}'


def release_alfworld_task(observation: str, *, json_example: str | None = None) -> str:
    """The first prompt of the released ALFWorld ReAct/Act (``prompts: release``), in the layout of
    ``react_alfworld/react.py:132-142`` (``act_alfworld/act.py:158-172`` adds a JSON request with an
    example, ``json_example``): a newline, a whitespace-only line, the rule under a heading, the
    task heading, then the first observation with its valid actions and a trailing newline. The
    sentences are ours."""
    ask = f"Answer with a JSON object holding an 'action' field, for instance:\n\n{json_example}\n\n" if json_example else ""
    return f"\n        \nThe environment's rule:\n{RELEASE_ALFWORLD_RULE}\n\n{ask}The task follows.\n\n{observation}\n"


def turn(observation: str, *, goal: str | None = None, subtask: str | None = None, feedback: str | None = None) -> str:
    """One turn's message: optional error feedback first, the observation, the goal when the
    observation does not already state it (Robotouille's does: the release sends it alone,
    ReAct_agent.py:232-235), and the executor's subtask last (ReAct_agent.py:232-239)."""
    parts = []
    if feedback:
        parts.append(f"Error feedback: {feedback}")
    parts.append(f"Observation:\n{observation}")
    if goal and goal not in observation:
        parts.append(f"Goal: {goal}")
    if subtask:
        parts.append(f"Subtask: {subtask}")
    return "\n\n".join(parts)


def invalid_action(action: str) -> str:
    """Feedback after an action that matches no valid action (ReAct_agent.py:279)."""
    return f"'{action}' does not match any of the valid actions. Choose one of the valid actions."


def planner_turn(observation: str, goal: str | None) -> str:
    """The planner's one message (ADaPT_agent.py:133-138)."""
    return turn(observation, goal=goal)


def planner_example(prompt: str, reply: str) -> str:
    """The planner's demonstration: one example message and its plan (the JSON planner's layout)."""
    return planner_transcript(prompt, reply, header="Here is an example of a goal split into subtasks.")
