"""How a number outside its range is refused: one wording for the sweep file, generation params,
method settings and test-double options (each keeps its own table of ranges)."""

from __future__ import annotations

from typing import Any


def number_text(v: float) -> str:
    """A number as a refusal shows it: integers in full, floats in their shortest form (1e-300)."""
    if isinstance(v, int) or (float(v).is_integer() and abs(v) < 1e16):
        return str(int(v))
    return repr(float(v))


def range_problem(value: Any, integer: bool, low: float, high: float) -> str | None:
    """Why ``value`` is not a number (an integer when ``integer``; never true/false) within
    ``[low, high]``, both ends inclusive; None when it is. Refuses nan."""
    kind = "an integer" if integer else "a number"
    if isinstance(value, bool) or not isinstance(value, int if integer else (int, float)):
        return f"must be {kind} in [{number_text(low)}, {number_text(high)}], got {value!r}"
    if not (low <= value <= high):
        return f"{number_text(value)} is out of range [{number_text(low)}, {number_text(high)}]"
    return None
