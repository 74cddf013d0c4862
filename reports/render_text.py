"""A query result as text: an aligned table, CSV or JSON (what ``recap sql`` prints).

Its own module so that ``recap sql``'s query process (:mod:`reports.sandbox`) prints with the same
code as the command, without importing the command.
"""

from __future__ import annotations

import json
import math
from typing import Any, TextIO

from reports.render_csv import result_csv
from reports.views import Result


def print_result(result: Result, fmt: str, max_rows: int, out: TextIO) -> None:
    """Write ``result`` as ``fmt``: ``table`` (at most ``max_rows`` rows), ``csv`` or ``json`` (every row)."""
    if fmt == "csv":
        out.write(result_csv(result))
    elif fmt == "json":
        out.write(
            json.dumps([{k: _json_value(v) for k, v in zip(result.columns, r)} for r in result.rows], indent=1, default=str)
            + "\n"
        )
    else:
        out.write(format_table(result, max_rows=max_rows))


def _json_value(v: Any) -> Any:
    if isinstance(v, float) and (math.isnan(v) or math.isinf(v)):
        return None
    if isinstance(v, tuple):
        return list(v)
    return v


def _text(v: Any, width: int) -> str:
    if v is None:
        s = "NULL"
    elif isinstance(v, float):
        s = f"{v:.6g}"
    else:
        s = str(v)
    s = " ".join(s.split()) if "\n" in s else s
    return s if len(s) <= width else s[: width - 1] + "…"


def format_table(result: Result, *, max_rows: int = 100, width: int = 60) -> str:
    """An aligned text table, numbers right-aligned, at most ``max_rows`` rows."""
    shown = result.rows[: max(max_rows, 0)]
    cells = [[_text(v, width) for v in row] for row in shown]

    def is_number(v: Any) -> bool:
        return isinstance(v, (int, float)) and not isinstance(v, bool)

    numeric = [
        any(r[i] is not None for r in shown) and all(is_number(r[i]) for r in shown if r[i] is not None)
        for i in range(len(result.columns))
    ]
    widths = [max([len(c)] + [len(row[i]) for row in cells]) for i, c in enumerate(result.columns)]

    def line(values: list[str]) -> str:
        return " | ".join(v.rjust(w) if numeric[i] else v.ljust(w) for i, (v, w) in enumerate(zip(values, widths))).rstrip()

    lines = [line(list(result.columns)), "-+-".join("-" * w for w in widths)]
    lines += [line(row) for row in cells]
    n = len(result.rows)
    more = n - len(shown)
    lines.append(
        f"({n} row{'s' if n != 1 else ''}" + (f"; {more} not shown, use --max-rows, --csv or --json)" if more > 0 else ")")
    )
    return "\n".join(lines) + "\n"
