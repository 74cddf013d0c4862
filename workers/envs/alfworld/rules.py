"""ALFWorld rule and hint texts for the prompts, in our own words.

The paper gives the agent one ALFWorld rule (a single item in hand; check with inventory when
unsure); we add the command vocabulary so the model knows the exact verb forms, because the game
silently ignores anything worded differently. Both the real games and the demonstration replays
use these texts, so every agent sees identical rules (the paper keeps rules identical across
agents).
"""

from __future__ import annotations

from workers.envs.alfworld.wording import check_version

_PUT_FORM = {"2.1.1": "put <object> in/on <receptacle>", "2.1.2": "move <object> to <receptacle>"}

_RULES = """\
You are in a household and act through short text commands. Places such as countertops,
cabinets, drawers, the fridge, the microwave or the sinkbasin are receptacles; every receptacle
and object has a number (cabinet 3, mug 2).
- You can hold only one object at a time. Whenever you are unsure what you are holding, or before
  you pick something up, check with "inventory".
- Commands:
  go to <receptacle> | open <receptacle> | close <receptacle>
  take <object> from <receptacle> | {put_form}
  heat <object> with <microwave> | cool <object> with <fridge> | clean <object> with <sinkbasin>
  use <lamp> | examine <object or receptacle> | inventory | look
- Write a command exactly as it appears among the valid actions. Anything else changes nothing,
  the game answers "Nothing happens.", and the attempt still uses one of your {max_steps} steps."""

_HINTS = """\
- Copy the command word for word from the valid actions, numbers included.
- Go to a receptacle before you take from it, put into it, open it or use something on it.
- A closed receptacle (drawer, cabinet, fridge, safe, microwave) must be opened before you can
  see inside it or put anything into it.
- You can take an object only with empty hands: put down what you hold first ("inventory" tells
  you what that is).
- To heat, cool or clean an object, hold it and go to the microwave, fridge or sinkbasin first.
- To look at an object under a lamp, hold it, go to where the lamp is, then use the lamp."""


def rules_text(version: str, max_steps: int) -> str:
    """The rules text in the wording of game-file ``version`` (its put/move command form) with the step cap
    ``max_steps``; ValueError for an unknown version."""
    return _RULES.format(put_form=_PUT_FORM[check_version(version)], max_steps=max_steps)


def failure_hints_text() -> str:
    """Hints shown after an invalid action; one text for every game and version (the game never says why a
    command did nothing)."""
    return _HINTS
