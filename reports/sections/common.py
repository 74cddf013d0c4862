"""What every report section shares: the named-query runner, pivot helpers, and the notes' common phrases."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

import duckdb

from reports.sections.fever_samples import load_fever_samples
from reports.sections.plans import load_plans
from reports.views import Result, named_query

Query = Callable[[str], Result]

#: Where the paper's numbers are: only the paper section puts them beside an arm, and only after
#: checking that the arm ran the paper's protocol (model, profile, window, step caps, tasks).
PAPER_POINTER = "The paper's values stand in the Paper section, beside arms that ran the paper's protocol."


def make_query(con: duckdb.DuckDBPyConnection, results: dict[str, Result]) -> Query:
    """Run each named SQL file once; keep every result for the CSV output. The run folders'
    plans are loaded first (:func:`load_plans`), for the coverage table, and the FEVER samples
    (:func:`load_fever_samples`), for the paper's FEVER numbers."""
    load_plans(con)
    load_fever_samples(con)

    def q(name: str) -> Result:
        if name not in results:
            results[name] = named_query(con, name)
        return results[name]

    return q


def unique(values: Iterable[Any]) -> list[Any]:
    """``values`` without repeats, in the order they first come."""
    seen: dict[Any, None] = {}
    for v in values:
        seen.setdefault(v, None)
    return list(seen)


def rate_ci(row: dict[str, Any]) -> tuple[int, int, float, float]:
    """A rate cell: (successes, episodes, interval low, interval high) of a success row."""
    return (row["successes"], row["episodes"], row["ci_low"], row["ci_high"])


def is_test_double(model_label: str) -> bool:
    """Whether the model label is a test double's (the SQL marks those labels)."""
    return model_label.endswith(" (test double)")


def row_order(key: tuple[str, str]) -> tuple[bool, str, str]:
    """Pivot rows: real models first, then test doubles; by model, then method."""
    return (is_test_double(key[0]), key[0], key[1])


def series_label(model: str, arm: str, models: list[str]) -> str:
    """A plot series or column: the arm, with its model when the report holds several models."""
    return arm if len(models) <= 1 else f"{arm} · {model}"


def comparisons_note(m: int, what: str, column: str = "Holm p") -> str:
    """How many tests a table's p column holds, and that its Holm column adjusts over them."""
    noun = what if m == 1 else what + "s"
    return f"{m} {noun} in this table; {column}: Holm-adjusted over {'it' if m == 1 else f'those {m}'} (family-wise error)."


def slug(text: str) -> str:
    """``text`` as a name part (letters and digits, ``_`` for the rest)."""
    return "".join(c if c.isalnum() else "_" for c in text).strip("_")
