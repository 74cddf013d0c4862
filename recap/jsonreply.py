"""Tolerant parsing of the model's JSON replies, and the shapes each agent expects.

Models wrap JSON in code fences, add prose around it, leave trailing commas or ``//`` comments
(the paper's own format example has comments) and sometimes use single quotes. We repair those
before giving up; anything else is a :class:`ReplyFormatError` whose message goes back to the
model in a bounded re-ask.
"""

from __future__ import annotations

import ast
import json
import re
from collections.abc import Mapping
from typing import Any


class ReplyFormatError(ValueError):
    """The reply is not the JSON object we asked for; the message tells the model why."""


_FENCE = re.compile(r"```(?:json|JSON)?\s*(.*?)```", re.S)
_TRAILING_COMMA = re.compile(r",\s*([}\]])")


def _strip_comments(text: str) -> str:
    """Remove // and /* */ comments outside string literals."""
    out: list[str] = []
    i, n = 0, len(text)
    in_str: str | None = None
    while i < n:
        c = text[i]
        if in_str:
            out.append(c)
            if c == "\\" and i + 1 < n:
                out.append(text[i + 1])
                i += 2
                continue
            if c == in_str:
                in_str = None
            i += 1
            continue
        if c in "\"'":
            in_str = c
            out.append(c)
            i += 1
        elif text.startswith("//", i):
            j = text.find("\n", i)
            i = n if j < 0 else j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            i = n if j < 0 else j + 2
        else:
            out.append(c)
            i += 1
    return "".join(out)


def _outer_object(text: str) -> str | None:
    """The substring from the first '{' to its matching '}' (string-aware)."""
    start = text.find("{")
    if start < 0:
        return None
    depth = 0
    in_str: str | None = None
    i = start
    while i < len(text):
        c = text[i]
        if in_str:
            if c == "\\":
                i += 2
                continue
            if c == in_str:
                in_str = None
        elif c in "\"'":
            in_str = c
        elif c == "{":
            depth += 1
        elif c == "}":
            depth -= 1
            if depth == 0:
                return text[start : i + 1]
        i += 1
    return None


def parse_json_object(text: str) -> dict[str, Any]:
    """Extract one JSON object from a model reply, repairing common slips."""
    if not text or not text.strip():
        raise ReplyFormatError("the reply was empty; answer with one JSON object")
    fenced = _FENCE.search(text)
    candidate = fenced.group(1) if fenced else text
    obj_text = _outer_object(candidate) or _outer_object(text)
    if obj_text is None:
        raise ReplyFormatError("no JSON object found in the reply; answer with one JSON object")
    cleaned = _TRAILING_COMMA.sub(r"\1", _strip_comments(obj_text))
    try:
        value = json.loads(cleaned)
    except json.JSONDecodeError as exc:
        try:
            value = ast.literal_eval(cleaned)
        except (ValueError, SyntaxError):
            raise ReplyFormatError(f"the reply is not valid JSON ({exc.msg} at position {exc.pos})") from None
    if not isinstance(value, dict):
        raise ReplyFormatError("the reply must be a JSON object, not " + type(value).__name__)
    return value


def _string(obj: Mapping[str, Any], key: str, *, required: bool) -> str | None:
    if key not in obj:
        if required:
            raise ReplyFormatError(f'the JSON object needs a "{key}" field (a string)')
        return None
    value = obj[key]
    if not isinstance(value, str):
        raise ReplyFormatError(f'"{key}" must be a string')
    return value


def _string_list(obj: Mapping[str, Any], key: str) -> tuple[str, ...]:
    if key not in obj:
        raise ReplyFormatError(f'the JSON object needs a "{key}" field (a list of strings)')
    value = obj[key]
    if isinstance(value, str):
        raise ReplyFormatError(f'"{key}" must be a list of strings, not a single string')
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise ReplyFormatError(f'"{key}" must be a list of strings')
    return tuple(v.strip() for v in value)


def recap_reply(obj: Mapping[str, Any], *, with_think: bool = True) -> dict[str, Any]:
    """{"think": str, "subtasks": [str]} (think optional when the ablation drops it)."""
    think = _string(obj, "think", required=with_think)
    return {"think": think if with_think else None, "subtasks": _string_list(obj, "subtasks")}


def action_reply(obj: Mapping[str, Any], *, with_think: bool) -> dict[str, Any]:
    """{"think": str, "action": str} for ReAct; {"action": str} for Act."""
    think = _string(obj, "think", required=with_think)
    action = _string(obj, "action", required=True)
    assert action is not None
    return {"think": think if with_think else None, "action": action.strip()}


def plan_reply(obj: Mapping[str, Any], *, with_think: bool) -> dict[str, Any]:
    """{"think": str, "actions": [str]} for CoT; {"actions": [str]} for Standard."""
    think = _string(obj, "think", required=with_think)
    return {"think": think if with_think else None, "actions": _string_list(obj, "actions")}


def dump_reply(reply: Mapping[str, Any]) -> str:
    """Serialise a reply the way demonstrations show it (stable key order, no None fields)."""
    return json.dumps(
        {k: (list(v) if isinstance(v, tuple) else v) for k, v in reply.items() if v is not None}, ensure_ascii=False
    )
