"""Terminal tables that fit the terminal by leaving columns out, never by cutting a name.

Rich shrinks a table wider than the console by cutting cells (``recap…`` for an arm named
``recap-level_2``), which hides which arm a row is. :func:`fitted_table` measures every column,
keeps the name columns whole (never wrapped or cut) and, while the table is too wide, leaves out
the column of least value (each column says its rank), saying in the caption which ones it left
out. Used by ``recap estimate``, ``recap status`` and ``recap run --dry-run``'s plan.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

from rich.cells import cell_len
from rich.markup import escape
from rich.table import Table


@dataclass(frozen=True)
class Col:
    """One column: its header, alignment, and ``drop`` - None for a column that always stays (the
    names), else its rank: the lowest rank is left out first when the table is too wide."""

    name: str
    justify: Literal["left", "right"] = "right"
    drop: int | None = None


def table_width(widths: Sequence[int]) -> int:
    """Characters a rich table (default box, padding 1) needs for columns of ``widths``."""
    return sum(widths) + 3 * len(widths) + 1


def print_fitted(console: Any, title: str, cols: Sequence[Col], rows: Sequence[Sequence[str]]) -> None:
    """Print :func:`fitted_table` on ``console`` (a rich Console) at its width; when the name columns
    alone are wider, the table is printed at the width they need, uncropped (the terminal wraps its
    lines: a name is never cut)."""
    t = fitted_table(title, cols, rows, console.width)
    need = table_width([c.min_width or 0 for c in t.columns])
    if need > console.width:
        console.print(t, width=need, crop=False)
    else:
        console.print(t)


def fitted_table(title: str, cols: Sequence[Col], rows: Sequence[Sequence[str]], width: int) -> Table:
    """A table of ``rows`` (plain text cells, one per column of ``cols``) within ``width`` columns:
    droppable columns left out, lowest rank first, until it fits (or none is left); the kept name
    columns are never wrapped or cut. Cells are printed as text (escaped), never as markup."""
    widths = [max([cell_len(c.name), *(cell_len(r[i]) for r in rows)]) for i, c in enumerate(cols)]
    kept = list(range(len(cols)))
    dropped: list[str] = []
    for i in sorted((i for i, c in enumerate(cols) if c.drop is not None), key=lambda i: (cols[i].drop or 0, -i)):
        if table_width([widths[k] for k in kept]) <= width:
            break
        kept.remove(i)
        dropped.append(cols[i].name)
    caption = f"left out to fit {width} columns: {', '.join(dropped)}" if dropped else None
    t = Table(title=escape(title), caption=escape(caption) if caption else None, caption_justify="left")
    for i in kept:
        c = cols[i]
        # a name stays whole, on one line; the others keep their width while the table fits
        t.add_column(escape(c.name), justify=c.justify, no_wrap=c.drop is None, min_width=widths[i])
    for r in rows:
        t.add_row(*(escape(r[i]) for i in kept))
    return t
