"""The text an agent reads from an ALFWorld game, real or replayed: the game's own answer,
optionally followed by the commands that are valid now.

With ``show_valid_actions`` on, every observation (the first one at reset and the answer to
every step, "Nothing happens." included) ends with the currently admissible commands, in the
environment's order, one per line after a blank line and a header line::

    You arrive at loc 31. On the garbagecan 1, you see a apple 2, a apple 1, and a egg 1.

    Valid actions:
    examine garbagecan 1
    go to cabinet 1
    ...
    take egg 1 from garbagecan 1

The list is exactly ``Step.valid_actions`` (``Reset.valid_actions`` at reset), so a command
copied from it is a valid action. The wording is ours; ReCAP's released code likewise appends
the admissible commands to every observation. With the setting off (the default) the
observation is the game's text alone, as in Yao et al.'s ReAct/Act prompts.
"""

from __future__ import annotations

from collections.abc import Sequence

#: the header line that introduces the list
VALID_ACTIONS_HEADER = "Valid actions:"
#: the line shown under the header when no command is valid (never seen in the real games)
NO_VALID_ACTIONS = "(none)"


def check_show_valid_actions(value: object, name: str = "show_valid_actions") -> bool:
    """The setting as the environment uses it: True/False as given, None (not decided by the
    environment; the caller fills it per method) means off. Anything else is an error that names
    the option (``name``)."""
    if value is None:
        return False
    if isinstance(value, bool):
        return value
    raise ValueError(f"{name} must be true, false or null (None), got {value!r}")


def with_valid_actions(text: str, valid: Sequence[str]) -> str:
    """``text``, a blank line, ``Valid actions:`` and one valid command per line."""
    lines = list(valid) or [NO_VALID_ACTIONS]
    return "\n".join([text, "", VALID_ACTIONS_HEADER, *lines])


def render_observation(text: str, valid: Sequence[str], show_valid_actions: bool) -> str:
    """The observation the agent sees: the game's text, plus the valid actions when shown."""
    return with_valid_actions(text, valid) if show_valid_actions else text
