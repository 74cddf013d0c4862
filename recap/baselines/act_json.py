"""The released ALFWorld Act's reading of its JSON replies (``malformed_json: game``).

The released act.py never repairs a reply (GitHub ``ReCAP-Stanford/ReCAP`` at 2fb112f,
``alfworld-recap/act_alfworld/act.py``): it strips backtick fences (``:122-131``) and calls
``json.loads`` (``:181-182``). What follows, as :func:`read_reply` returns it and
:meth:`recap.baselines.react.ReActAgent.play` acts on it:

* text that is not JSON becomes the command ``json parse error`` (``:183-184``), which is sent
  to the game like any command: the game answers it and counts a step (``:192``); the next
  message is not that answer but a note that the reply was not a valid JSON object
  (``:197-199``; :data:`MALFORMED_JSON`, our words). The command string is what the game
  receives, so it is the release's;
* an ``action`` that is empty (or not text) becomes the command ``error`` (``:190-191``), an
  invalid command the game answers like any other;
* a reply with a ``think`` and no ``action`` is a thought ("OK.", ``:218-219``);
* an object with neither repeats the previous message (``:221``: ``ob`` is unchanged).
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from typing import Any

#: act.py:122: every run of backticks, with a "json" after it, is removed
_FENCE = re.compile(r"`+(?:json)?", re.IGNORECASE)
#: the command act.py:184 sends to the game for a reply that is not JSON
PARSE_ERROR_ACTION = "json parse error"
#: the command act.py:190-191 sends for an empty action
EMPTY_ACTION = "error"
#: the message after a reply that is not JSON (our words; act.py:198 says the same)
MALFORMED_JSON = "Your reply was not a valid JSON object. Reply with one JSON object that has an 'action' field."


@dataclass(frozen=True)
class ReleasedReply:
    """One reply as the released Act reads it: ``malformed`` (not JSON), or the ``action`` to send
    (None: none) and the ``think`` it carries (None: none)."""

    malformed: bool
    action: str | None = None
    think: str | None = None

    def as_reply(self) -> dict[str, Any]:
        """The reply dict ReAct's loop works with."""
        return {"think": self.think, "action": self.action}


def read_reply(text: str) -> ReleasedReply:
    """Read one reply as act.py:181-191 does (see the module docstring)."""
    try:
        value = json.loads(_FENCE.sub("", text))
    except ValueError:
        return ReleasedReply(True, PARSE_ERROR_ACTION)
    if not isinstance(value, dict):
        # act.py would fail on ``'action' in <not a dict>``; read as not JSON
        return ReleasedReply(True, PARSE_ERROR_ACTION)
    think = value.get("think") if isinstance(value.get("think"), str) else None
    if "action" not in value:
        return ReleasedReply(False, None, think)
    action = value["action"]
    return ReleasedReply(False, action if isinstance(action, str) and action else EMPTY_ACTION, think)
