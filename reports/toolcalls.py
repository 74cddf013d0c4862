"""Tool calls for people: an assistant message's calls read back from their JSON, a call's outcome in
a few words, and an episode's totals.

Shared by ``recap show`` (pipeline) and ``recap view`` (reports), so both tell a call's story the same
way. Everything here is model-written text (a call's name and arguments, a tool's output): callers
escape it for their medium; :func:`one_line` only keeps a terminal line one line.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class MessageCall:
    """One call an assistant message made (``messages.tool_calls``): its id, tool name and the raw
    arguments the model wrote."""

    id: str
    name: str
    arguments: str


def message_calls(raw: str | None) -> list[MessageCall] | None:
    """The calls of ``messages.tool_calls`` in the model's order: [] for none (null), None when the
    text is not the ``[{"id", "name", "arguments"}]`` JSON the runtime writes (shown raw instead)."""
    if raw is None:
        return []
    try:
        items = json.loads(raw)
    except ValueError:
        return None
    if not isinstance(items, list) or not all(isinstance(i, dict) for i in items):
        return None
    out = []
    for i in items:
        args = i.get("arguments")
        out.append(
            MessageCall(
                "" if i.get("id") is None else str(i["id"]),
                "" if i.get("name") is None else str(i["name"]),
                args if isinstance(args, str) else json.dumps(args),
            )
        )
    return out


def one_line(text: str | None, width: int = 160) -> str:
    """``text`` on one line (line breaks and tabs written as ``\\n``, ``\\r``, ``\\t``, other control
    characters dropped) cut to ``width`` characters with "..."; "" for none."""
    s = (text or "").replace("\\", "\\\\").replace("\n", "\\n").replace("\r", "\\r").replace("\t", "\\t")
    s = "".join(c for c in s if c.isprintable())
    return s if len(s) <= width else s[: width - 3] + "..."


def outcome(row: Mapping[str, Any]) -> str:
    """What became of one ``tool_calls`` row, in a few words: ``invalid: <error>``, ``timed out after
    1.50 s``, ``exit 0 · 0.25 s · 6 bytes`` (``error: ...`` appended when a call that ran reports one)."""
    if not row["valid"] and row["exit_code"] is None and not row["timed_out"]:
        return f"invalid: {row['error'] or 'no reason given'}"
    if row["timed_out"]:
        head = f"timed out after {row['duration_s']:.2f} s · {row['output_bytes']:,} bytes"
    else:
        code = "no exit code" if row["exit_code"] is None else f"exit {row['exit_code']}"
        head = f"{code} · {row['duration_s']:.2f} s · {row['output_bytes']:,} bytes"
    return head + (f" · error: {row['error']}" if row["error"] else "")


@dataclass(frozen=True)
class ToolTotals:
    """An episode's tool calls counted: all, invalid ones, timed-out ones, time spent and output made."""

    calls: int
    invalid: int
    timed_out: int
    duration_s: float
    output_bytes: int

    def line(self) -> str:
        """The summary line ``recap show`` prints and the viewer heads its table with."""
        return (
            f"tool calls: {self.calls} ({self.invalid} invalid, {self.timed_out} timed out) · "
            f"{self.duration_s:.2f} s · {self.output_bytes:,} output bytes"
        )


def totals(rows: Iterable[Mapping[str, Any]]) -> ToolTotals:
    """The totals of an episode's ``tool_calls`` rows (the numbers of the ``tool_stats`` view)."""
    rows = list(rows)
    return ToolTotals(
        calls=len(rows),
        invalid=sum(1 for r in rows if not r["valid"]),
        timed_out=sum(1 for r in rows if r["timed_out"]),
        duration_s=sum(float(r["duration_s"]) for r in rows),
        output_bytes=sum(int(r["output_bytes"]) for r in rows),
    )


def rows_by_call(rows: Iterable[Mapping[str, Any]]) -> dict[tuple[int | None, str], Mapping[str, Any]]:
    """The ``tool_calls`` rows of one episode keyed by (the assistant message that made it, call id);
    rows without a call id (commands written as text) are left out: no message names them."""
    return {(r["message_seq"], r["call_id"]): r for r in rows if r["call_id"] is not None}


def answered_call(messages: Iterable[Mapping[str, Any]]) -> dict[int, int | None]:
    """For each ``tool`` message (by seq), the seq of the assistant message whose call it answers: the
    latest one before it that made a call with its ``tool_call_id`` (None when no message did)."""
    latest: dict[str, int] = {}
    out: dict[int, int | None] = {}
    for m in sorted(messages, key=lambda m: m["seq"]):
        for c in message_calls(m.get("tool_calls")) or []:
            latest[c.id] = m["seq"]
        if m.get("tool_call_id") is not None:
            out[m["seq"]] = latest.get(m["tool_call_id"])
    return out
