"""Observation text for people: a text's first line, and what an observation adds to the one before.

Shared by `recap show` (pipeline) and `recap view` (reports), so both print a step the same way.
"""

from __future__ import annotations


def first_line(text: str | None, width: int = 120) -> str:
    """The first line of ``text`` (leading blank lines skipped), cut to ``width`` characters (with "..."); "" for no text."""
    line = (text or "").strip().splitlines()[0] if (text or "").strip() else ""
    return line if len(line) <= width else line[: width - 1] + "..."


def observation_change(prev: str | None, cur: str | None, width: int = 120) -> str:
    """What an observation says that the one before it did not: its new lines, in order, joined
    by " | " (Robotouille repeats the whole kitchen each step, so its first line never changes).
    An unchanged observation reads "(no change)"; the first step is compared with nothing (all of
    its lines but the object headers)."""
    seen = set((prev or "").splitlines())
    new = [
        line.strip() for line in (cur or "").splitlines() if line.strip() and line not in seen and not line.rstrip().endswith(":")
    ]
    text = " | ".join(new) if new else ("(no change)" if prev is not None else first_line(cur, width))
    return text if len(text) <= width else text[: width - 3] + "..."
