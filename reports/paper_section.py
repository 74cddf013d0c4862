"""The ``paper`` section: the ReCAP paper's tables, laid out as in the paper, filled from a run.

Every number comes from ``reports/sql/paper_cells.sql``, ``paper_pairs.sql`` and
``paper_trees.sql``; this module only picks cells, pivots them into the paper's layout and adds
the paper's numbers (:mod:`reports.paper`). A success cell is four columns: ours as
``rate [95% CI] k/n`` (Wilson's interval widened for repeated seeds of one instance: the SQL
macros ``cluster_wilson_low/high``), the paper's value, the difference in points, and a McNemar
p-value against ReCAP on the units both arms ran (ablations: against the original), clustered by
instance (``clustered_mcnemar_p``: the exact McNemar test when each instance ran one seed), with
Holm's adjustment over the table beside it. Cost p-values flip the signs of whole instances
(:func:`reports.stats.clustered_permutation_test`). Each table's note names its interval and
tests from the cells it shows (:mod:`reports.stat_notes`).

A paper number stands only beside an arm that ran the paper's protocol for that table (model,
profile, window, step multipliers, tasks: :func:`reports.paper.mismatch`); elsewhere the paper
cell holds a footnote mark ``[n]`` and the table's note says why. A table whose protocol the run
did not follow at all is left out; the ``paper_omitted`` table says, in one line each, what is
missing. Each laid-out table is also added to the report's results (``paper_table_<name>``), so
the CSV output holds the tables exactly as shown.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable
from typing import Any

from reports import paper
from reports.model import Column, Section, Table, format_value
from reports.stat_notes import interval_note, mcnemar_note, permutation_note
from reports.stats import SignFlipTest, clustered_permutation_test, holm
from reports.views import Result

Query = Callable[[str], Result]

BENCH_ROWS = (
    ("alfworld", None, "ALFWorld"),
    ("robotouille", "synchronous", "Robotouille (Sync)"),
    ("robotouille", "asynchronous", "Robotouille (Async)"),
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


def _join(*parts: str) -> str:
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
    )


def rate_ci(cell: dict[str, Any]) -> tuple[int, int, float, float]:
    """A cell's ``rate_ci`` value: (successes, episodes, CI low, CI high) as the renderers expect it."""
    return (cell["successes"], cell["episodes"], cell["ci_low"], cell["ci_high"])


def _rate_columns(key: str, header: str) -> list[Column]:
    return [
        Column(key, header, "rate_ci"),
        Column(f"{key}:paper", "paper", "text"),
        Column(f"{key}:diff", "diff", "ref"),
        Column(f"{key}:p", "p", "p"),
        Column(f"{key}:holm", "p Holm", "p"),
    ]


def _fill_rate(
    row: dict[str, Any], key: str, cell: dict[str, Any], ref: float | None, why: str | None, notes: Footnotes, p: float | None
) -> None:
    """One success cell: ours, the paper's value (or a footnote mark), the difference, p."""
    row[key] = rate_ci(cell)
    if ref is not None and why is None:
        row[f"{key}:paper"] = format_value("ref", ref)
        row[f"{key}:diff"] = 100.0 * cell["successes"] / cell["episodes"] - ref
    elif ref is not None and why is not None:
        row[f"{key}:paper"] = notes.mark(why)
    row[f"{key}:p"] = p


def _add_holm(rows: list[dict[str, Any]], keys: Iterable[str]) -> int:
    """Holm over every p of the table; returns how many comparisons the table makes."""
    slots = [(r, k) for r in rows for k in keys if r.get(f"{k}:p") is not None]
    adjusted = holm([r[f"{k}:p"] for r, k in slots])
    for (r, k), a in zip(slots, adjusted):
        r[f"{k}:holm"] = a
    return len(slots)


def _method_rank(order: tuple[str, ...], method: str) -> int:
    return order.index(method) if method in order else len(order)


def _test_double_last(model_label: str) -> tuple[bool, str]:
    return (model_label.endswith(" (test double)"), model_label)


def _same_protocol(a: dict[str, Any], b: dict[str, Any]) -> bool:
    return list(a["profiles"]) == list(b["profiles"]) and list(a["windows"]) == list(b["windows"])


class _Cells:
    """paper_cells and paper_pairs rows, indexed for the layouts."""

    def __init__(self, q: Query) -> None:
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
            and (cell["method"] != "recap" or _same_protocol(r, cell))
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


def _p(cells: _Cells, cell: dict[str, Any], pool: list[dict[str, Any]], used: list[dict[str, Any]]) -> float | None:
    """The McNemar p of ``cell`` against its reference; the pair row is appended to ``used`` (for the note)."""
    if cell["method"] == "recap" and cell["ablation"] == "original":
        return None
    pr = cells.pair(cell, cells.reference(cell, pool))
    if pr:
        used.append(pr)
    return pr["p_value"] if pr else None


def _test_notes(shown: list[dict[str, Any]], used: list[dict[str, Any]]) -> str:
    """The note's words for a success table's intervals (the cells ``shown``) and p-values (the pairs ``used``)."""
    return _join(interval_note(shown), mcnemar_note((u["pairs"], u["instances"]) for u in used))


# -- the tables ------------------------------------------------------------------------------------


def main_table(cells: _Cells) -> Table | str:
    """Paper Table 1 (pass@1 per benchmark and method) from the arms without an ablation; or, when no arm fits,
    the one line that says why it is left out."""
    pool = [
        c
        for c in cells.select(level="split")
        if c["ablation"] == "original"
        and (
            c["benchmark"] == "alfworld"
            or (c["benchmark"], c["split"]) in (("robotouille", "synchronous"), ("robotouille", "asynchronous"))
        )
    ]
    if not pool:
        return "Main results: no arm without an ablation ran Robotouille (synchronous or asynchronous) or ALFWorld."
    arms = sorted({(c["method"], c["arm_label"]) for c in pool}, key=lambda a: (_method_rank(paper.MAIN_ORDER, a[0]), a[1]))
    cols = [Column("benchmark", "benchmark"), Column("model", "model")]
    for _, label in arms:
        cols += _rate_columns(label, label)
    notes = Footnotes()
    used: list[dict[str, Any]] = []
    rows: list[dict[str, Any]] = []
    row_keys = sorted(
        {(c["benchmark"], c["split"], c["model_label"]) for c in pool},
        key=lambda k: (
            next(i for i, b in enumerate(BENCH_ROWS) if b[0] == k[0] and b[1] in (None, k[1])),
            k[1],
            _test_double_last(k[2]),
        ),
    )
    for bench, split, model in row_keys:
        title = next(t for b, s, t in BENCH_ROWS if b == bench and s in (None, split))
        row: dict[str, Any] = {
            "benchmark": title if bench != "alfworld" or split == "valid_unseen" else f"{title} ({split})",
            "model": model,
        }
        for c in pool:
            if (c["benchmark"], c["split"], c["model_label"]) != (bench, split, model):
                continue
            ref = paper.main_reference(f"{bench}/{split}", c["method"])
            why = paper.FOREIGN.get((bench, c["method"])) or paper.mismatch(paper.PROTOCOLS["main"], arm_protocol(c))
            _fill_rate(row, c["arm_label"], c, ref, why, notes, _p(cells, c, pool, used))
        rows.append(row)
    m = _add_holm(rows, [a[1] for a in arms])
    note = _join(
        "Columns: method arms in the paper's order (ReCAP, ADaPT, ReAct, CoT, Act, Standard). p: against the ReCAP "
        f"arm of the same model, profile and window; {m} comparisons (Holm over the table).",
        _test_notes(pool, used),
        notes.text(),
    )
    return Table(
        "paper_main", "Main results: pass@1 (%) by benchmark and method (paper Table 1)", cols, rows, "paper_cells", note
    )


def per_task_tables(cells: _Cells, split: str) -> list[Table] | str:
    """Paper Table 5 or 6 (per-task pass@1 on Robotouille ``split``), one table per model; or the one line that
    says why they are left out."""
    pool_task = [c for c in cells.select(level="task", benchmark="robotouille", split=split) if c["ablation"] == "original"]
    pool_split = [c for c in cells.select(level="split", benchmark="robotouille", split=split) if c["ablation"] == "original"]
    if not pool_task:
        return f"Per-task table ({split}): no arm without an ablation ran Robotouille {split} tasks."
    tables = []
    models = sorted({c["model_label"] for c in pool_task}, key=_test_double_last)
    number = {"synchronous": 5, "asynchronous": 6}[split]
    for model in models:
        mt = [c for c in pool_task if c["model_label"] == model]
        ms = [c for c in pool_split if c["model_label"] == model]
        arms = sorted({(c["method"], c["arm_label"]) for c in mt}, key=lambda a: (_method_rank(paper.TASK_ORDER, a[0]), a[1]))
        cols = [Column("task", "task")]
        for _, label in arms:
            cols += _rate_columns(label, label)
        notes = Footnotes()
        used: list[dict[str, Any]] = []
        rows = []
        tasks = sorted({c["task"] for c in mt}, key=lambda t: (paper.task_index(t) is None, paper.task_index(t) or 0, t))
        for task in tasks:
            row: dict[str, Any] = {"task": task}
            idx = paper.task_index(task)
            for c in mt:
                if c["task"] != task:
                    continue
                ref = paper.PER_TASK[split].get(idx, {}).get(c["method"]) if idx is not None else None
                why = paper.mismatch(paper.PROTOCOLS["per_task"], arm_protocol(c), [f"{split}:{idx}"])
                _fill_rate(row, c["arm_label"], c, ref, why, notes, _p(cells, c, mt, used))
            rows.append(row)
        avg: dict[str, Any] = {"task": "Average"}
        for c in ms:
            ref = paper.PER_TASK_AVERAGE[split].get(c["method"])
            why = paper.mismatch(paper.PROTOCOLS["per_task"], arm_protocol(c))
            _fill_rate(avg, c["arm_label"], c, ref, why, notes, _p(cells, c, ms, used))
        rows.append(avg)
        m = _add_holm(rows, [a[1] for a in arms])
        note = _join(
            f"model: {model}. Rows: the benchmark's tasks in order (the paper shows each recipe as a picture); "
            "Average: all episodes of the split pooled (the paper's average of ten equal tasks). Columns: the "
            f"paper's order (ReCAP, ReAct, ADaPT, Act, CoT, Std). p: against ReCAP; {m} comparisons "
            "(Holm over the table).",
            _test_notes(mt + ms, used),
            notes.text(),
        )
        slug = re.sub(r"[^0-9A-Za-z]+", "_", model).strip("_")
        tables.append(
            Table(
                f"paper_tasks_{split}_{slug}",
                f"Robotouille {split}: pass@1 (%) per task (paper Table {number})",
                cols,
                rows,
                "paper_cells",
                note,
            )
        )
    return tables


def cross_model_table(cells: _Cells) -> Table | str:
    """Paper Table 2 (ReAct and ReCAP across models on synchronous tasks 2, 4, 6, 64-message window); or the one
    line that says why it is left out."""
    pool = [
        c
        for c in cells.select(scope="sync_2_4_6", level="split")
        if c["method"] in ("react", "recap") and c["ablation"] == "original" and list(c["windows"]) == [64]
    ]
    # the table compares the two methods per model: a model counts only when both ran at 64 messages.
    # The main tables' runs do not make it by themselves: there ReAct keeps 64 messages on Robotouille
    # (the released baseline) but ReCAP 128 (the paper's K = 64 rounds)
    both = {
        m for m in {c["model_label"] for c in pool} if {c["method"] for c in pool if c["model_label"] == m} == {"react", "recap"}
    }
    pool = [c for c in pool if c["model_label"] in both]
    if not pool:
        return (
            "Cross-model table: no model has both a ReAct and a ReCAP arm without an ablation on Robotouille "
            "synchronous tasks 2, 4, 6 with a 64-message window."
        )
    order = list(paper.CROSS_MODEL)

    def model_rank(model: str) -> tuple[int, bool, str]:
        # the paper's column order; a model string the paper does not name is placed by its label
        pm = {paper.paper_model(m) for c in pool if c["model_label"] == model for m in c["provider_models"]}
        pm.add(paper.paper_model(model.removesuffix(" (test double)")))
        idx = min((order.index(p) for p in pm if p in order), default=len(order))
        return (idx, *_test_double_last(model))

    models = sorted({c["model_label"] for c in pool}, key=model_rank)
    arms = sorted({(c["method"], c["arm_label"]) for c in pool}, key=lambda a: (a[0] != "react", a[1]))
    cols = [Column("method", "method")]
    for model in models:
        cols += _rate_columns(model, model)
    notes = Footnotes()
    used: list[dict[str, Any]] = []
    rows = []
    for method, label in arms:
        row: dict[str, Any] = {"method": label}
        for c in pool:
            if c["arm_label"] != label:
                continue
            proto = arm_protocol(c)
            pm = paper.paper_model(proto.provider_model)
            why = paper.mismatch(paper.PROTOCOLS["cross_model"], proto)
            # a model the paper did not run still gets its footnote (why is then always set)
            ref = paper.CROSS_MODEL.get(pm or "", paper.CROSS_MODEL["gpt-4o"] if why else {}).get(method)
            _fill_rate(row, c["model_label"], c, ref, why, notes, _p(cells, c, pool, used))
        rows.append(row)
    m = _add_holm(rows, models)
    note = _join(
        "Robotouille synchronous tasks 2, 4 and 6, 64-message window. p (on the ReAct rows): against ReCAP of the "
        f"same model on the same units; {m} comparisons (Holm over the table).",
        _test_notes(pool, used),
        notes.text(),
    )
    return Table(
        "paper_cross_model",
        "Success rates (%) of ReAct and ReCAP across models, Robotouille tasks 2, 4, 6 (paper Table 2)",
        cols,
        rows,
        "paper_cells",
        note,
    )


def ablation_table(cells: _Cells) -> Table | str:
    """Paper Table 3 (ReCAP ablations on synchronous task 6, 128-message window), each variant against the
    original; or the one line that says why it is left out."""
    pool = [
        c
        for c in cells.select(level="task", benchmark="robotouille", split="synchronous")
        if c["method"] == "recap" and paper.task_index(c["task"]) == 6 and list(c["windows"]) == [128]
    ]
    if not any(c["ablation"] != "original" for c in pool):
        return "Ablation table: no ReCAP ablation ran Robotouille synchronous task 6 with a 128-message window."
    variants = sorted(
        {c["ablation"] for c in pool},
        key=lambda v: (list(paper.ABLATIONS).index(v) if v in paper.ABLATIONS else len(paper.ABLATIONS), v),
    )
    row_keys = sorted(
        {(c["model_label"], ",".join(p or "none" for p in c["profiles"])) for c in pool},
        key=lambda k: (*_test_double_last(k[0]), k[1]),
    )
    cols = [Column("model", "model"), Column("profile", "profile")]
    for v in variants:
        cols += _rate_columns(v, v)
    notes = Footnotes()
    used: list[dict[str, Any]] = []
    rows = []
    for model, profile in row_keys:
        row: dict[str, Any] = {"model": model, "profile": profile}
        mine = sorted(
            (c for c in pool if c["model_label"] == model and ",".join(p or "none" for p in c["profiles"]) == profile),
            key=lambda c: c["arm_label"],
        )
        for v in variants:
            c = next((c for c in mine if c["ablation"] == v), None)
            if c is None:
                continue
            why = paper.mismatch(paper.PROTOCOLS["ablations"], arm_protocol(c))
            p = None
            if v != "original":
                ref = next((r for r in mine if r["ablation"] == "original"), None)
                pr = cells.pair(c, ref)
                p = pr["p_value"] if pr else None
                if pr:
                    used.append(pr)
            _fill_rate(row, v, c, paper.ABLATIONS.get(v), why, notes, p)
        rows.append(row)
    m = _add_holm(rows, variants)
    note = _join(
        "Robotouille synchronous task 6, 128-message window; columns in the paper's order. p: each variant against "
        f"the original (same model and profile) on the units both ran; {m} comparisons (Holm over the table).",
        _test_notes(pool, used),
        notes.text(),
    )
    return Table(
        "paper_ablations",
        "ReCAP variants: success rate (%) on Robotouille synchronous task 6 (paper Table 3)",
        cols,
        rows,
        "paper_cells",
        note,
    )


def _cost_test(pr: dict[str, Any]) -> SignFlipTest:
    """The permutation test of a pair row's cost differences, flipping whole instances."""
    return clustered_permutation_test(pr["cost_diffs"], pr["cost_instances"])


def _cost_p(cells: _Cells, cell: dict[str, Any], pool: list[dict[str, Any]], used: list[SignFlipTest]) -> float | None:
    """The cost p of ``cell`` against its reference; the test is appended to ``used`` (for the note)."""
    if cell["method"] == "recap" and cell["ablation"] == "original":
        return None
    pr = cells.pair(cell, cells.reference(cell, pool))
    if not pr:
        return None
    used.append(_cost_test(pr))
    return used[-1].p


def alfworld_cost_tables(cells: _Cells) -> list[Table] | str:
    """The ALFWorld cost tables (totals per method, and the ReCAP/ReAct ratio on the games both ran); or the one
    line that says why they are left out."""
    pool = [c for c in cells.select(level="split", benchmark="alfworld") if c["ablation"] == "original"]
    if not pool:
        return "ALFWorld costs: no arm without an ablation ran ALFWorld."
    pool.sort(key=lambda c: (*_test_double_last(c["model_label"]), _method_rank(paper.MAIN_ORDER, c["method"]), c["arm_label"]))
    notes = Footnotes()
    tests: list[SignFlipTest] = []
    totals = paper.COSTS["alfworld_134_games_usd"]
    rows = []
    for c in pool:
        ref = totals.get(c["method"])
        why = paper.mismatch(paper.PROTOCOLS["costs_alfworld"], arm_protocol(c))
        if why is None and c["episodes"] != paper.ALFWORLD_GAMES:
            why = f"ran {c['episodes']} of the paper's {paper.ALFWORLD_GAMES} games: totals differ in size"
        row = {
            "model": c["model_label"],
            "method": c["arm_label"],
            "games": c["episodes"],
            "calls": c["calls"],
            "tokens": c["tokens"],
            "cost": c["cost_usd"],
            "per_game": c["cost_per_episode"],
            "p": _cost_p(cells, c, pool, tests),
        }
        if ref is not None and why is None:
            row["paper"], row["diff"] = f"${ref:,.2f}", c["cost_usd"] - ref
        elif ref is not None and why is not None:
            row["paper"] = notes.mark(why)
        rows.append(row)
    totals_t = Table(
        "paper_costs_alfworld",
        "ALFWorld: total cost per method over the games run (paper: 134 games)",
        [
            Column("model", "model"),
            Column("method", "method"),
            Column("games", "games", "int"),
            Column("calls", "LLM calls", "int"),
            Column("tokens", "tokens", "int"),
            Column("cost", "total $", "usd"),
            Column("per_game", "$/game", "usd"),
            Column("paper", "paper total", "text"),
            Column("diff", "diff $", "usd"),
            Column("p", "p ($ vs ReCAP)", "p"),
        ],
        rows,
        "paper_cells",
        _join(
            "p: the per-game cost difference against ReCAP of the same model, profile and window, on the games both ran.",
            permutation_note(tests, "p"),
            notes.text(),
        ),
    )
    ratio_notes = Footnotes()
    ratio_tests: list[SignFlipTest] = []
    ratio_rows = []
    paper_ratio = totals["recap"] / totals["react"]
    for c in pool:
        if c["method"] != "react":
            continue
        ref_cell = cells.reference(c, pool)
        pr = cells.pair(c, ref_cell)
        if ref_cell is None or pr is None or not pr["arm_cost"]:
            continue
        why = paper.mismatch(paper.PROTOCOLS["costs_alfworld"], arm_protocol(c)) or paper.mismatch(
            paper.PROTOCOLS["costs_alfworld"], arm_protocol(ref_cell)
        )
        row = {
            "model": c["model_label"],
            "recap": ref_cell["arm_label"],
            "react": c["arm_label"],
            "games": pr["pairs"],
            "recap_cost": pr["ref_cost"],
            "react_cost": pr["arm_cost"],
            "ratio": pr["ref_cost"] / pr["arm_cost"],
            "p": _cost_test(pr).p,
        }
        ratio_tests.append(_cost_test(pr))
        if why is None:
            row["paper"], row["diff"] = f"{paper_ratio:.2f}", row["ratio"] - paper_ratio
        else:
            row["paper"] = ratio_notes.mark(why)
        ratio_rows.append(row)
    out = [totals_t]
    if ratio_rows:
        out.append(
            Table(
                "paper_cost_ratio",
                "ALFWorld: ReCAP/ReAct cost ratio on the games both ran (paper: $118.40 / $37.89)",
                [
                    Column("model", "model"),
                    Column("recap", "ReCAP arm"),
                    Column("react", "ReAct arm"),
                    Column("games", "games", "int"),
                    Column("recap_cost", "ReCAP $", "usd"),
                    Column("react_cost", "ReAct $", "usd"),
                    Column("ratio", "ratio", "float"),
                    Column("paper", "paper", "text"),
                    Column("diff", "diff", "float"),
                    Column("p", "p", "p"),
                ],
                ratio_rows,
                "paper_pairs",
                _join(
                    "ratio = ReCAP's total / ReAct's total over the paired games; p: the per-game cost difference.",
                    permutation_note(ratio_tests, "p"),
                    ratio_notes.text(),
                ),
            )
        )
    return out


def task6_cost_table(cells: _Cells) -> Table | str:
    """The task-6 cost table (calls, tokens and dollars per episode on synchronous task 6); or the one line that
    says why it is left out."""
    pool = [
        c
        for c in cells.select(level="task", benchmark="robotouille", split="synchronous")
        if paper.task_index(c["task"]) == 6 and c["ablation"] == "original"
    ]
    if not pool:
        return "Task-6 costs: no arm without an ablation ran Robotouille synchronous task 6."
    pool.sort(key=lambda c: (*_test_double_last(c["model_label"]), _method_rank(paper.MAIN_ORDER, c["method"]), c["arm_label"]))
    ref = paper.COSTS["robotouille_sync_task6"]
    notes = Footnotes()
    tests: list[SignFlipTest] = []
    rows = []
    for c in pool:
        row = {
            "model": c["model_label"],
            "method": c["arm_label"],
            "window": ", ".join(str(w) for w in c["windows"]),
            "episodes": c["episodes"],
            "calls": c["calls_per_episode"],
            "calls_sd": c["calls_sd"],
            "tokens": c["tokens_per_episode"],
            "cost": c["cost_per_episode"],
            "cost_sd": c["cost_sd"],
            "p": _cost_p(cells, c, pool, tests),
        }
        if c["method"] == "recap":
            why = paper.mismatch(paper.PROTOCOLS["costs_task6"], arm_protocol(c))
            if why is None:
                row["paper_calls"] = f"{ref['calls_per_episode']:.2f} (sd {ref['calls_sd']:.2f})"
                row["diff_calls"] = c["calls_per_episode"] - ref["calls_per_episode"]
                row["paper_cost"] = f"${ref['usd_per_episode']:.2f} (sd ${ref['usd_sd']:.2f})"
                row["diff_cost"] = c["cost_per_episode"] - ref["usd_per_episode"]
            else:
                row["paper_calls"] = row["paper_cost"] = notes.mark(why)
        rows.append(row)
    return Table(
        "paper_costs_task6",
        "Robotouille synchronous task 6: LLM calls, tokens and dollars per episode (paper: ReCAP, GPT-4o)",
        [
            Column("model", "model"),
            Column("method", "method"),
            Column("window", "window"),
            Column("episodes", "episodes", "int"),
            Column("calls", "calls/episode", "float"),
            Column("calls_sd", "sd", "float"),
            Column("tokens", "tokens/episode", "tokens"),
            Column("cost", "$/episode", "usd"),
            Column("cost_sd", "sd", "usd"),
            Column("paper_calls", "paper calls", "text"),
            Column("diff_calls", "diff calls", "float"),
            Column("paper_cost", "paper $", "text"),
            Column("diff_cost", "diff $", "usd"),
            Column("p", "p ($ vs ReCAP)", "p"),
        ],
        rows,
        "paper_cells",
        _join(
            "The paper's task-6 cost is taken to come from its 20 task-6 runs (128-message window, as its tree analysis). "
            "p: the per-episode cost difference against ReCAP of the same model, profile and window.",
            permutation_note(tests, "p"),
            notes.text(),
        ),
    )


def tree_table(q: Query) -> Table | str:
    """The task-tree statistics (depth and branching of ReCAP's trees on synchronous task 6) beside the paper's;
    or the one line that says why it is left out."""
    trees = [t for t in q("paper_trees").dicts() if t["method"] == "recap" and t["ablation"] == "original"]
    if not trees:
        return "Tree statistics: no ReCAP arm without an ablation has task trees on Robotouille synchronous task 6."
    trees.sort(key=lambda t: (*_test_double_last(t["model_label"]), t["arm_label"]))
    notes = Footnotes()
    rows = []
    for t in trees:
        row = {
            "model": t["model_label"],
            "method": t["arm_label"],
            "window": ", ".join(str(w) for w in t["windows"]),
            "episodes": t["episodes"],
            "levels": t["mean_levels"],
            "levels_sd": t["levels_sd"],
            "branching": t["mean_branching"],
            "branching_sd": t["branching_sd"],
        }
        why = paper.mismatch(paper.PROTOCOLS["trees"], arm_protocol(t))
        if why is None:
            row["paper_depth"], row["diff_depth"] = f"{paper.TREE['depth']:.1f}", t["mean_levels"] - paper.TREE["depth"]
            row["paper_branching"] = f"{paper.TREE['branching_factor']:.1f}"
            row["diff_branching"] = None if t["mean_branching"] is None else t["mean_branching"] - paper.TREE["branching_factor"]
        else:
            row["paper_depth"] = row["paper_branching"] = notes.mark(why)
        rows.append(row)
    return Table(
        "paper_trees",
        "Task trees on Robotouille synchronous task 6: depth and branching factor (paper §Task Tree Analysis)",
        [
            Column("model", "model"),
            Column("method", "method"),
            Column("window", "window"),
            Column("episodes", "episodes", "int"),
            Column("levels", "depth (levels)", "float"),
            Column("levels_sd", "sd", "float"),
            Column("branching", "branching", "float"),
            Column("branching_sd", "sd", "float"),
            Column("paper_depth", "paper depth", "text"),
            Column("diff_depth", "diff depth", "float"),
            Column("paper_branching", "paper branching", "text"),
            Column("diff_branching", "diff branching", "float"),
        ],
        rows,
        "paper_trees",
        _join(
            "depth = levels of the tree, the root being level 1 (the level_N ablations' convention); branching = mean "
            "children per node that has children; both per episode, then averaged. The paper defines neither and "
            "reports no test here.",
            notes.text(),
        ),
    )


def paper_section(q: Query, results: dict[str, Result] | None = None) -> Section:
    """The section; with ``results``, each laid-out table is added as ``paper_table_<name>``."""
    cells = _Cells(q)
    sec = Section("paper", "The paper's tables", INTRO)
    omitted: list[dict[str, str]] = []
    built: list[Table | list[Table] | str] = [
        main_table(cells),
        per_task_tables(cells, "synchronous"),
        per_task_tables(cells, "asynchronous"),
        cross_model_table(cells),
        ablation_table(cells),
        alfworld_cost_tables(cells),
        task6_cost_table(cells),
        tree_table(q),
    ]
    for item in built:
        if isinstance(item, str):
            table, _, missing = item.partition(": ")
            omitted.append({"table": table, "missing": missing})
        elif isinstance(item, list):
            sec.tables.extend(item)
        else:
            sec.tables.append(item)
    if omitted:
        sec.tables.append(
            Table(
                "paper_omitted",
                "Paper tables left out: what the run did not run",
                [Column("table", "table"), Column("missing", "what is missing")],
                omitted,
                "paper_cells",
            )
        )
    if results is not None:
        for t in sec.tables:
            results[f"paper_table_{t.name.removeprefix('paper_')}"] = Result(
                [c.key for c in t.columns], [tuple(format_value(c.kind, r.get(c.key)) for c in t.columns) for r in t.rows]
            )
    return sec
