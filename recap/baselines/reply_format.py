"""The ``reply_format`` setting of the baselines: one check and the released profile's choice.

Why its own module: ReAct, Act, CoT and Standard each have the setting (``json``: our JSON
replies; ``text``: the released code's plain-text replies, :mod:`recap.baselines.textreply`),
and the rule that goes with it is the same for all of them.
"""

from __future__ import annotations

from typing import Any

from recap.config import AgentConfig, ConfigError


def check_reply_format(cfg: AgentConfig) -> None:
    """``reply_format`` is json or text, and text is never sent in JSON mode (the provider would
    force a JSON object on a reply that must be plain lines)."""
    fmt = getattr(cfg, "reply_format", "json")
    if fmt not in ("json", "text"):
        raise ConfigError(f"reply_format must be json or text, got {fmt!r}")
    if fmt == "text" and cfg.json_mode:
        raise ConfigError("reply_format: text needs json_mode: false (the replies are plain text)")


#: what ``released`` sets on any benchmark: plain text as the released agents write it (the
#: labelled lines of Robotouille's release); a benchmark whose release reads something else says
#: so in its protocol (ALFWorld: ReAct's one-line layout, JSON for Act and the plans)
RELEASED_TEXT: dict[str, Any] = {"reply_format": "text", "json_mode": False}
