"""Counts in words for every message and table of the project: "1 file", "2 files", never "1 files".

One helper so the rule is the same everywhere (``recap data check``, ``recap status``, the estimate,
the viewer's summaries): English plurals of the nouns the project counts, with the irregular ones
given by the caller.
"""

from __future__ import annotations

__all__ = ["count", "plural"]


def plural(n: float, noun: str, many: str | None = None) -> str:
    """``noun`` for a count of ``n`` (1: singular), else ``many`` or ``noun`` + ``s``
    (``es`` after s, x, z, ch, sh; ``ies`` after a consonant + y)."""
    if n == 1:
        return noun
    if many is not None:
        return many
    if noun.endswith(("s", "x", "z", "ch", "sh")):
        return noun + "es"
    if noun.endswith("y") and noun[-2:-1] not in ("a", "e", "i", "o", "u", ""):
        return noun[:-1] + "ies"
    return noun + "s"


def count(n: int, noun: str, many: str | None = None) -> str:
    """``"1 file"``, ``"2 files"``, ``"1234 episodes"``: ``n`` and its noun.
    A noun phrase (``"instance image"``) takes its plural on its last word."""
    head, _, last = noun.rpartition(" ")
    word = plural(n, last, many)
    return f"{n} {head + ' ' if head else ''}{word}"
