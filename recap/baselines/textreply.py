"""The released baselines' plain-text reply formats: parsers, action matching and renderers.

Why its own module: under ``reply_format: text`` ReAct, Act, CoT, Standard and the released
ADaPT read the model's reply the way the authors' released code reads it (GitHub
``ReCAP-Stanford/ReCAP`` at 2fb112f), not as JSON. Each rule below cites the release's
file:line. The renderers are the parsers' inverse (``parse(render(x)) == x``); demonstrations
and the offline test doubles write replies with them, so every layout is spoken by one piece of
code and read back by another.

Layouts (``LAYOUTS``; an agent tells the offline doubles which one in ``hints["text_layout"]``):

* ``reasoning_action``: ``Reasoning: ...`` then ``Action: ...`` (Robotouille's ReAct and the
  ADaPT executor, ``robotouille-baselines/agents/ReAct_agent.py:26-27``);
* ``action``: ``Action: ...`` alone (Robotouille's Act, ``Act_agent.py:27,261``);
* ``think_or_action``: one line, either ``think: ...`` or the command itself (Yao et al.'s
  ALFWorld ReAct as released, ``alfworld-recap/react_alfworld/react.py:152-160``);
* ``plan``: ``Plan:`` then one action per line (Robotouille's I/O agent, ``IO_agent.py:20,166-175``);
* ``action_lines``: every line starting ``Action:`` is one planned action, other lines
  (reasoning, predicted state changes) are ignored (I/O-CoT, ``IOCoT_agent.py:20,148``);
* ``step_plan``: reasoning, ``Step <n>: ...`` lines and one ``Execution order: ...`` line with
  an AND/OR expression (the ADaPT planner, ``ADaPT_agent.py:12-13,161-235``).
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

LAYOUTS = ("reasoning_action", "action", "think_or_action", "plan", "action_lines", "step_plan")

#: the reply that ends a ReAct run (ReAct_agent.py:28,272: compared exactly, after strip)
FINISH_ACTION = "Finish"

# ReAct_agent.py:26: "everything up till Action" -- greedy, so up to the *last* "Action:"
_REASONING = re.compile(r"^Reasoning:\s*(.+)Action:", re.M | re.S)
# ReAct_agent.py:27 / Act_agent.py:27 / IOCoT_agent.py:20: the first line that starts with
# "Action:"; \s* may cross a line break, (.+) stops at the end of a line
_ACTION = re.compile(r"^Action:\s*(.+)", re.M)
# IO_agent.py:20: everything after the first line-initial "Plan:"
_PLAN = re.compile(r"^Plan:\s*(.+)", re.M | re.S)
# ADaPT_agent.py:12-13
_STEP = re.compile(r"^Step\s*(\d+):\s*(.+)$", re.M)
_EXEC = re.compile(r"Execution\s*order\s*:\s*(.+)", re.I)
_EXPR_TOKEN = re.compile(r"Step\s+\d+|AND|OR|\(|\)")
# ReAct_agent.py:294 / IO_agent.py:196: what matching ignores
_PUNCTUATION = re.compile(r"[^\w\s]")


@dataclass(frozen=True)
class TextReply:
    """One parsed reply of the ReAct-like layouts: the thought, the action, or why it is
    malformed (``error``: the feedback the release sends back; the reply is then unusable)."""

    think: str | None = None
    action: str | None = None
    error: str | None = None

    @property
    def finish(self) -> bool:
        """The reply ends the run (ReAct_agent.py:272)."""
        return self.action == FINISH_ACTION


#: feedback after a malformed reply, in our words, carrying what ReAct_agent.py:256,263 says
MISSING_REASONING = "Your reply has no reasoning. Write it on a line that starts with 'Reasoning: '."
MISSING_ACTION = "Your reply has no action. Write it on a line that starts with 'Action: '."


def _search(regex: re.Pattern[str], text: str) -> str | None:
    """``group(1)`` of the first match, or None (ReAct_agent.py:155-171 ``_regex_match``)."""
    m = regex.search(text)
    return m.group(1) if m else None


def parse_reasoning_action(text: str, *, with_think: bool) -> TextReply:
    """ReAct (``with_think``) or Act. ReAct needs a ``Reasoning:`` line before the action
    (ReAct_agent.py:254-258); both need an ``Action:`` line (ReAct_agent.py:261-265,
    Act_agent.py:261-265); the action is stripped (ReAct_agent.py:266). An empty capture counts
    as missing, as ``if not reasoning`` does in the release."""
    think = None
    if with_think:
        think = _search(_REASONING, text)
        if not think:
            return TextReply(error=MISSING_REASONING)
    action = _search(_ACTION, text)
    if not action:
        return TextReply(think=think, error=MISSING_ACTION)
    return TextReply(think=think, action=action.strip())


def parse_think_or_action(text: str) -> TextReply:
    """Yao et al.'s ALFWorld line as the release reads it: the reply stops at its first line
    break (the request's ``stop=["\\n"]``, react.py:152), is stripped, loses a leading
    ``assistant`` label (react.py:153-154), and is a thought when ``think:`` occurs anywhere in it
    (react.py:159); anything else is the command sent to the game as it is (react.py:155)."""
    line = text.split("\n", 1)[0].strip()
    if line[:9] == "assistant":
        line = line[10:].strip()
    if "think:" in line:
        return TextReply(think=line)
    return TextReply(action=line)


def normalize(action: str) -> str:
    """Punctuation removed, lower case (ReAct_agent.py:294, IO_agent.py:196)."""
    return _PUNCTUATION.sub("", action).lower()


def matching_actions(action: str, valid: Sequence[str]) -> list[str]:
    """The valid actions whose normalized text *contains* the normalized ``action``, in the
    environment's order (ReAct_agent.py:291-308, IO_agent.py:193-210). Containment, as released:
    ``table1`` matches ``table10`` too, and an action that is all punctuation matches every one."""
    needle = normalize(action)
    return [v for v in valid if needle in normalize(v)]


def match_action(action: str, valid: Sequence[str]) -> str | None:
    """ReAct/Act: the first matching valid action (ReAct_agent.py:282), or None."""
    found = matching_actions(action, valid)
    return found[0] if found else None


def unique_match(action: str, valid: Sequence[str]) -> str | None:
    """CoT/Standard: the matching valid action when exactly one matches (IO_agent.py:180), else None."""
    found = matching_actions(action, valid)
    return found[0] if len(found) == 1 else None


def parse_plan(text: str) -> list[str] | None:
    """Standard (I/O): the lines after ``Plan:``, each stripped (IO_agent.py:166-175), blank
    ones included (a blank line matches every valid action and so fails the plan check, as
    released); None when there is no ``Plan:`` line."""
    block = _search(_PLAN, text)
    if not block:
        return None
    return [line.strip() for line in block.split("\n")]


def parse_action_lines(text: str) -> list[str] | None:
    """CoT (I/O-CoT): every ``Action:`` line's action, stripped (IOCoT_agent.py:148); None when
    there is none."""
    actions = [a.strip() for a in _ACTION.findall(text)]
    return actions or None


# -- the ADaPT planner's plan ------------------------------------------------------------------------


def _parse_expression(expression: str) -> dict[str, Any]:
    """The execution-order expression as nested groups (ADaPT_agent.py:187-205): ``Step n``
    adds a step to the current group, ``AND``/``OR`` set the group's logic (the last one
    written wins), parentheses open and close groups (an unmatched ``)`` starts over)."""
    stack: list[dict[str, Any]] = []
    current: dict[str, Any] = {}
    for token in _EXPR_TOKEN.findall(expression):
        if token.startswith("Step"):
            current.setdefault("steps", []).append(int(token.split()[1]))
        elif token in ("AND", "OR"):
            current["logic"] = token
        elif token == "(":
            stack.append(current)
            current = {}
        else:
            closed = current
            current = stack.pop() if stack else {}
            current.setdefault("steps", []).append(closed)
    return current


def _fill(lookup: Mapping[int, str], group: dict[str, Any]) -> dict[str, Any]:
    """Step numbers replaced by their text; an unknown number becomes ``Step <n>``
    (ADaPT_agent.py:207-215)."""
    steps = [lookup.get(s, f"Step {s}") if isinstance(s, int) else _fill(lookup, s) for s in group.get("steps", [])]
    return {**group, "steps": steps}


def _flatten(group: Mapping[str, Any]) -> list[str]:
    """The subtasks to run, in order: an OR group contributes only its first branch, any other
    group every branch (ADaPT_agent.py:217-235)."""
    steps = group.get("steps", [])
    logic = group.get("logic", "")
    logic = logic.upper() if isinstance(logic, str) else ""
    if logic == "OR" and steps:
        steps = steps[:1]
    out: list[str] = []
    for s in steps:
        out.extend([s] if isinstance(s, str) else _flatten(s))
    return out


def parse_step_plan(text: str) -> list[str]:
    """The released planner's subtasks (ADaPT_agent.py:161-185): the ``Step <n>:`` lines by
    number (a repeated number keeps its last text); with an ``Execution order:`` line, the
    expression's order with OR groups cut to their first branch; without one, or if the
    expression cannot be read, every step in number order. No step line: ``[]``."""
    lookup: dict[int, str] = {}
    for m in _STEP.finditer(text):
        lookup[int(m.group(1))] = m.group(2).strip()
    if not lookup:
        return []
    in_order = [lookup[n] for n in sorted(lookup)]
    order = _search(_EXEC, text)
    if order is None:
        return in_order
    try:
        return _flatten(_fill(lookup, _parse_expression(order.strip())))
    except Exception:  # noqa: BLE001  (ADaPT_agent.py:183-185 falls back to number order on any error)
        return in_order


# -- renderers (demonstrations and the offline doubles) ------------------------------------------------


def render_step_plan(think: str, subtasks: Sequence[str], logic: str = "and") -> str:
    """A planner reply: the reasoning, ``Plan:``, the steps, and their execution order joined by
    ``logic`` (the layout of the release's planner example)."""
    joiner = " OR " if logic.lower() == "or" else " AND "
    steps = [f"Step {i}: {s}" for i, s in enumerate(subtasks, 1)]
    order = joiner.join(f"Step {i}" for i in range(1, len(subtasks) + 1))
    return "\n".join([think, "", "Plan:", *steps, f"Execution order: {order}"])


def render(layout: str, reply: Mapping[str, Any]) -> str:
    """The text of ``reply`` (the fields an agent declares: ``think``, ``action``, ``actions``,
    ``subtasks``, optional ``logic``) in ``layout``. ``think_or_action`` writes the thought line
    when the reply has no action."""
    think = reply.get("think")
    if layout == "reasoning_action":
        return f"Reasoning: {think}\n\nAction: {reply['action']}"
    if layout == "action":
        return f"Action: {reply['action']}"
    if layout == "think_or_action":
        if reply.get("action"):
            return str(reply["action"])
        return f"think: {think}"
    if layout == "plan":
        return "Plan:\n" + "\n".join(reply["actions"])
    if layout == "action_lines":
        head = [str(think), ""] if think else []
        return "\n".join([*head, *(f"Action: {a}" for a in reply["actions"])])
    if layout == "step_plan":
        return render_step_plan(str(think or ""), reply["subtasks"], str(reply.get("logic", "and")))
    raise ValueError(f"unknown text layout {layout!r}; known: {', '.join(LAYOUTS)}")
