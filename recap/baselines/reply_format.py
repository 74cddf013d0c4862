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


def text_reply_defaults(text_on_alfworld: bool, benchmark: str | None) -> dict[str, Any]:
    """What ``released`` sets: plain text as the release's agent writes it. On ALFWorld only
    where its ALFWorld script reads plain text (``text_on_alfworld``: ReAct's one-line layout);
    elsewhere Robotouille's labelled lines."""
    if benchmark == "alfworld":
        if not text_on_alfworld:
            return {}
        return {"reply_format": "text", "json_mode": False, "text_layout": "yao"}
    return {"reply_format": "text", "json_mode": False}
