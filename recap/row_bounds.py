"""How long a model-written field may be in a row, and how a longer one is cut.

Why: a model (or a provider that answers for it) writes a call's arguments, its id and its
tool name; a hostile one writes 5 MB of arguments or a 1 MB id. The agent and the provider keep
the whole text (the conversation goes on as written), but a row of the ``tool_calls``,
``steps`` or ``messages`` table holds at most these many characters of each: the rest is cut,
and the cut says so with the original length, so a reader sees that and how much was left out.
Pure functions, no I/O.
"""

from __future__ import annotations

#: characters of a call's arguments (and of a step's action) kept in a row
MAX_ARGUMENTS_CHARS = 65_536
#: characters of a call id or a tool name kept in a row
MAX_NAME_CHARS = 256


def cut(text: str, limit: int) -> str:
    """``text`` when it has at most ``limit`` characters, else its first ``limit`` followed by
    `` [cut: N characters in all]`` (N the original length)."""
    if len(text) <= limit:
        return text
    return f"{text[:limit]} [cut: {len(text)} characters in all]"
