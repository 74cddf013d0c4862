"""The paper section's cells: picking a run's cells for a paper table, footnotes, and the p-values beside them."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

from reports import paper
from reports.model import Column, format_value
from reports.stat_notes import interval_note, mcnemar_note
from reports.stats import holm
from reports.views import Result

Query = Callable[[str], Result]

BENCH_ROWS = (
    ("alfworld", None, "ALFWorld"),
    ("robotouille", "synchronous", "Robotouille (Sync)"),
    ("robotouille", "asynchronous", "Robotouille (Async)"),
    ("fever", None, "FEVER"),
    ("swe-verified", None, "SWE-bench Verified"),
)

INTRO = (
    "The ReCAP paper's tables, filled from this run. A success cell is: ours as success % [95% interval] "
    "successes/episodes (Wilson's interval, widened by the design effect when an instance ran with several seeds), "
    "the paper's value, ours minus the paper's in points (diff), and a McNemar p-value against ReCAP on the "
    "units both arms ran (ablations: against the original; the arms swapped per instance with all its seeds, the "
    "exact McNemar test when each instance ran one seed), with Holm's adjustment over the table. Each table's note "
    "names its interval and tests. Only units that "
    "finished on their own merits count (capped and infrastructure-failed units are in the coverage table). A paper "
    "number stands only beside an arm run under the paper's protocol for that table (model, profile, window, step "
    "multipliers, tasks); otherwise its cell holds a mark [n] and the note says why."
)


class Footnotes:
    """Numbered reasons why a paper number is not shown (one list per table)."""

    def __init__(self) -> None:
        self.reasons: dict[str, int] = {}

    def mark(self, reason: str) -> str:
        """The footnote mark for ``reason`` ("[1]", "[2]", ...): one number per distinct reason, in first-use order."""
        n = self.reasons.setdefault(reason, len(self.reasons) + 1)
        return f"[{n}]"

    def text(self) -> str:
        """The table note listing every reason under its mark; "" when none was used."""
        return " ".join(f"[{n}] {r}." for r, n in self.reasons.items())


def join_notes(*parts: str) -> str:
    """The non-empty note parts, one space apart."""
    return " ".join(p for p in parts if p)


def arm_protocol(cell: dict[str, Any]) -> paper.ArmProtocol:
    """What the arm of a paper_cells / paper_trees row ran."""
    models = [m for m in cell["provider_models"] if m is not None]
    profiles = list(cell["profiles"])
    if "task_multipliers" in cell:
        tasks = tuple((t["task"], tuple(t["multipliers"])) for t in cell["task_multipliers"])
    else:
        tasks = ((cell["task"], tuple(cell["multipliers"])),)
    return paper.ArmProtocol(
        provider_model=", ".join(models) if models else None,
        test_double=bool(cell["test_double"]),
        profile=profiles[0] if len(profiles) == 1 else ("mixed" if profiles else None),
        windows=tuple(cell["windows"]),
        benchmark=cell["benchmark"],
        split=cell["split"],
        tasks=tasks,
        method=cell.get("method") or "recap",
        episodes=cell.get("episodes"),
        instances=cell.get("instances"),
    )


def rate_ci(cell: dict[str, Any]) -> tuple[int, int, float, float]:
    """A cell's ``rate_ci`` value: (successes, episodes, CI low, CI high) as the renderers expect it."""
    return (cell["successes"], cell["episodes"], cell["ci_low"], cell["ci_high"])


def rate_columns(key: str, header: str) -> list[Column]:
    """A success cell's five columns: ours, the paper's value, the difference, p and Holm p."""
    return [
        Column(key, header, "rate_ci"),
        Column(f"{key}:paper", "paper", "text"),
        Column(f"{key}:diff", "diff", "ref"),
        Column(f"{key}:p", "p", "p"),
        Column(f"{key}:holm", "p Holm", "p"),
    ]


def fill_rate(
    row: dict[str, Any], key: str, cell: dict[str, Any], ref: float | None, why: str | None, notes: Footnotes, p: float | None
) -> None:
    """One success cell: ours, the paper's value (or a footnote mark), the difference, p."""
    row[key] = rate_ci(cell)
    if ref is not None and why is None:
        row[f"{key}:paper"] = paper_value(ref)
        row[f"{key}:diff"] = 100.0 * cell["successes"] / cell["episodes"] - ref
    elif ref is not None and why is not None:
        row[f"{key}:paper"] = notes.mark(why)
    row[f"{key}:p"] = p


def paper_value(ref: float) -> str:
    """The paper's number as the paper prints it: one decimal, or two where it gives two (SWE-bench's 39.58)."""
    return format_value("ref", ref) if round(ref, 1) == ref else f"{ref:.2f}"


def add_holm(rows: list[dict[str, Any]], keys: Iterable[str]) -> int:
    """Holm over every p of the table; returns how many comparisons the table makes."""
    slots = [(r, k) for r in rows for k in keys if r.get(f"{k}:p") is not None]
    adjusted = holm([r[f"{k}:p"] for r, k in slots])
    for (r, k), a in zip(slots, adjusted):
        r[f"{k}:holm"] = a
    return len(slots)


def method_rank(order: tuple[str, ...], method: str) -> int:
    """Where ``method`` stands in a table's method order (unknown ones last; mini-SWE-agent in ReAct's place)."""
    method = paper.COLUMN_OF.get(method, method)
    return order.index(method) if method in order else len(order)


def test_double_last(model_label: str) -> tuple[bool, str]:
    """Sort key: real models first, then test doubles; by label."""
    return (model_label.endswith(" (test double)"), model_label)


def same_protocol(a: dict[str, Any], b: dict[str, Any]) -> bool:
    """Whether two cells ran the same profiles and windows (so a paired test between them is fair)."""
    return list(a["profiles"]) == list(b["profiles"]) and list(a["windows"]) == list(b["windows"])


class Cells:
    """paper_cells and paper_pairs rows, indexed for the layouts."""

    def __init__(self, q: Query) -> None:
        #: for the queries only some tables need (SWE-bench Verified's temperatures)
        self.q = q
        self.cells = q("paper_cells").dicts()
        self.pairs = q("paper_pairs").dicts()
        self._pairs = {
            (r["scope"], r["model_label"], r["arm_label"], r["ref_label"], r["benchmark"], r["split"], r["level"], r["task"]): r
            for r in self.pairs
        }

    def select(self, *, scope: str = "all", level: str, **where: Any) -> list[dict[str, Any]]:
        out = []
        for c in self.cells:
            if c["scope"] != scope or c["level"] != level:
                continue
            if all((v(c[k]) if callable(v) else c[k] == v) for k, v in where.items()):
                out.append(c)
        return out

    def reference(self, cell: dict[str, Any], pool: list[dict[str, Any]]) -> dict[str, Any] | None:
        """The ReCAP (original) cell ``cell`` is compared with: same model, benchmark, split,
        task and profile; the same window for a ReCAP variant, and preferred for another method,
        whose window is its own protocol's (the paper's ReAct keeps 64 messages on Robotouille,
        its ReCAP 128); then the first by arm label."""
        refs = [
            r
            for r in pool
            if r["method"] == "recap"
            and r["ablation"] == "original"
            and r["arm_label"] != cell["arm_label"]
            and r["model_label"] == cell["model_label"]
            and (r["benchmark"], r["split"], r["task"]) == (cell["benchmark"], cell["split"], cell["task"])
            and list(r["profiles"]) == list(cell["profiles"])
            and (cell["method"] != "recap" or same_protocol(r, cell))
        ]
        return min(refs, key=lambda r: (list(r["windows"]) != list(cell["windows"]), r["arm_label"])) if refs else None

    def pair(self, cell: dict[str, Any], ref: dict[str, Any] | None) -> dict[str, Any] | None:
        if ref is None:
            return None
        return self._pairs.get(
            (
                cell["scope"],
                cell["model_label"],
                cell["arm_label"],
                ref["arm_label"],
                cell["benchmark"],
                cell["split"],
                cell["level"],
                cell["task"],
            )
        )


def paired_p(cells: Cells, cell: dict[str, Any], pool: list[dict[str, Any]], used: list[dict[str, Any]]) -> float | None:
    """The McNemar p of ``cell`` against its reference; the pair row is appended to ``used`` (for the note)."""
    if cell["method"] == "recap" and cell["ablation"] == "original":
        return None
    pr = cells.pair(cell, cells.reference(cell, pool))
    if pr:
        used.append(pr)
    return pr["p_value"] if pr else None


def test_notes(shown: list[dict[str, Any]], used: list[dict[str, Any]]) -> str:
    """The note's words for a success table's intervals (the cells ``shown``) and p-values (the pairs ``used``)."""
    return join_notes(interval_note(shown), mcnemar_note((u["pairs"], u["instances"]) for u in used))
