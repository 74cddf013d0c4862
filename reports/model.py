"""What a report is, independent of its output format: sections of tables and plots.

Builders (``reports/sections/``) fill these from SQL results; renderers (Markdown, HTML,
LaTeX, CSV) only lay them out, so every format shows the same numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from reports.views import Result, SkippedPart

#: value kinds a column can have; they decide formatting in every renderer
KINDS = ("text", "int", "float", "ref", "pct", "usd", "tokens", "p", "list", "rate_ci")


@dataclass(frozen=True)
class Column:
    """One column of a displayed table: the row key it shows, its header, and its value ``kind`` (one of KINDS),
    which decides how every renderer formats it."""

    key: str
    header: str
    kind: str = "text"

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"unknown column kind {self.kind!r}")


@dataclass
class Table:
    """A displayed table. ``source`` names the SQL file its numbers come from."""

    name: str
    title: str
    columns: list[Column]
    rows: list[dict[str, Any]]
    source: str
    note: str = ""


@dataclass
class Plot:
    """One figure of a section, as finished SVG text; ``source`` names the SQL file its numbers come from."""

    name: str
    title: str
    svg: str
    source: str
    note: str = ""


@dataclass
class Section:
    """One part of the report (overview, success, costs, ...): an introduction, then its tables and plots."""

    key: str
    title: str
    intro: str = ""
    tables: list[Table] = field(default_factory=list)
    plots: list[Plot] = field(default_factory=list)


@dataclass
class Report:
    """A built report: every section with its numbers already computed, ready for any renderer; ``skipped`` lists
    part files that could not be read."""

    title: str
    run_dirs: list[str]
    skipped: list[SkippedPart]
    sections: list[Section]
    #: every SQL result the report used, by query name (written as CSV)
    results: dict[str, Result]
    viewer_html: str = ""
    viewer_episodes: list[str] = field(default_factory=list)
    #: run_id -> the run's name (run.json's ``run``), which the HTML tables show for a run id (issue 36 item 8)
    run_names: dict[str, str] = field(default_factory=dict)


# -- formatting ---------------------------------------------------------------------------------


def _is_missing(v: Any) -> bool:
    return v is None or (isinstance(v, float) and math.isnan(v))


def format_value(kind: str, v: Any) -> str:
    """The text of one cell (the same in Markdown, HTML and LaTeX before escaping)."""
    if kind == "rate_ci":
        return format_rate_ci(v)
    if _is_missing(v):
        return "–"
    if kind == "int":
        return f"{int(v):,}"
    if kind == "float":
        return f"{float(v):,.2f}"
    if kind == "ref":
        return f"{float(v):.1f}"
    if kind == "pct":
        return f"{100 * float(v):.1f}"
    if kind == "usd":
        x = float(v)
        return f"-${-x:,.4f}" if x < 0 else f"${x:,.4f}"
    if kind == "tokens":
        return f"{float(v):,.0f}"
    if kind == "p":
        x = float(v)
        return "<0.0001" if x < 1e-4 else f"{x:.4f}"
    if kind == "list":
        return ", ".join(str(x) for x in v)
    return str(v)


def format_rate_ci(v: Any) -> str:
    """``(successes, episodes, ci_low, ci_high)`` as ``80.0 [37.6, 96.4] 4/5``."""
    if _is_missing(v):
        return "–"
    k, n, lo, hi = v
    if not n:
        return "–"
    return f"{100 * k / n:.1f} [{100 * lo:.1f}, {100 * hi:.1f}] {k}/{n}"
