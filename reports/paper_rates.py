"""The paper's success tables filled from a run: the main table, per task, cross-model and the ablations."""

from __future__ import annotations

import re
from typing import Any

from reports import paper
from reports.model import Column, Table
from reports.paper_cells import (
    BENCH_ROWS,
    Cells,
    Footnotes,
    add_holm,
    arm_protocol,
    fill_rate,
    join_notes,
    method_rank,
    paired_p,
    rate_columns,
    test_double_last,
    test_notes,
)
from reports.paper_swe import SWE_NOTE, swe_mismatch

#: a cell (or pair) of :class:`Cells`: column name to value
Cell = dict[str, Any]
#: a row of a table being filled: column name to value
Row = dict[str, Any]


def main_table(cells: Cells) -> Table | str:
    """Paper Table 1 (pass@1 per benchmark and method) from the arms without an ablation; or, when no arm fits,
    the one line that says why it is left out."""
    pool = [
        c
        for c in cells.select(level="split")
        if c["ablation"] == "original"
        and (
            c["benchmark"] in ("alfworld", "fever", paper.SWE_VERIFIED)
            or (c["benchmark"], c["split"]) in (("robotouille", "synchronous"), ("robotouille", "asynchronous"))
        )
    ]
    if not pool:
        return (
            "Main results: no arm without an ablation ran Robotouille (synchronous or asynchronous), ALFWorld, FEVER "
            "or SWE-bench Verified."
        )
    arms = sorted({(c["method"], c["arm_label"]) for c in pool}, key=lambda a: (method_rank(paper.MAIN_ORDER, a[0]), a[1]))
    cols = [Column("benchmark", "benchmark"), Column("model", "model")]
    for _, label in arms:
        cols += rate_columns(label, label)
    notes = Footnotes()
    used: list[Cell] = []
    rows: list[Row] = []
    row_keys = sorted(
        {(c["benchmark"], c["split"], c["model_label"]) for c in pool},
        key=lambda k: (
            next(i for i, b in enumerate(BENCH_ROWS) if b[0] == k[0] and b[1] in (None, k[1])),
            k[1],
            test_double_last(k[2]),
        ),
    )
    for bench, split, model in row_keys:
        title = next(t for b, s, t in BENCH_ROWS if b == bench and s in (None, split))
        row: Row = {
            "benchmark": title if bench != "alfworld" or split == "valid_unseen" else f"{title} ({split})",
            "model": model,
        }
        for c in pool:
            if (c["benchmark"], c["split"], c["model_label"]) != (bench, split, model):
                continue
            ref = paper.main_reference(f"{bench}/{split}", c["method"])
            if bench == paper.SWE_VERIFIED:
                why = swe_mismatch(cells, c)
            elif bench == "fever":
                c, why = fever_sample_cell(cells, c)
            else:
                why = paper.FOREIGN.get((bench, c["method"])) or paper.mismatch(paper.PROTOCOLS["main"], arm_protocol(c))
            fill_rate(row, c["arm_label"], c, ref, why, notes, paired_p(cells, c, pool, used))
        rows.append(row)
    m = add_holm(rows, [a[1] for a in arms])
    note = join_notes(
        "Columns: method arms in the paper's order (ReCAP, ADaPT, ReAct, CoT, Act, Standard). p: against the ReCAP "
        f"arm of the same model, profile and window; {m} comparisons (Holm over the table).",
        SWE_NOTE if any(c["benchmark"] == paper.SWE_VERIFIED for c in pool) else "",
        paper.FEVER_NOTE if any(c["benchmark"] == "fever" for c in pool) else "",
        test_notes(pool, used),
        notes.text(),
    )
    return Table(
        "paper_main", "Main results: pass@1 (%) by benchmark and method (paper Table 1)", cols, rows, "paper_cells", note
    )


def fever_sample_cell(cells: Cells, c: Cell) -> tuple[Cell, str | None]:
    """A FEVER arm's cell over the sample behind its method's paper number
    (:data:`reports.paper.FEVER_SAMPLE_SEED`) and why the paper's number may not stand beside it
    (None: it may); the arm's whole cell with the reason when that sample cannot be told or was not run.
    A reason that no sample can undo (a test double, another model, profile or window) comes first."""
    seed = paper.FEVER_SAMPLE_SEED.get(c["method"])
    whole = paper.mismatch(paper.PROTOCOLS["main"], arm_protocol(c))
    if seed is None:
        return c, whole
    if whole is not None and not whole.endswith(f"the paper ran {paper.FEVER_CLAIMS}"):
        return c, whole  # a test double, another model, profile or window: no sample makes it the paper's number
    scoped = [
        s
        for s in cells.select(scope=f"fever_seed{seed}", level="split", benchmark="fever", split=c["split"])
        if (s["arm_label"], s["model_label"]) == (c["arm_label"], c["model_label"])
    ]
    if not scoped:
        if not any(s["scope"].startswith("fever_seed") for s in cells.cells):
            return c, f"the paper's sample (seed {seed}) cannot be told here: no paper_dev.jsonl (set FEVER_DATA)"
        return c, f"none of the paper's sample for it (seed {seed}) ran"
    cell = scoped[0]
    why = paper.mismatch(paper.PROTOCOLS["main"], arm_protocol(cell))
    return cell, (f"{why} of its sample (seed {seed})" if why and "claims" in why else why)


def per_task_tables(cells: Cells, split: str) -> list[Table] | str:
    """Paper Table 5 or 6 (per-task pass@1 on Robotouille ``split``), one table per model; or the one line that
    says why they are left out."""
    pool_task = [c for c in cells.select(level="task", benchmark="robotouille", split=split) if c["ablation"] == "original"]
    pool_split = [c for c in cells.select(level="split", benchmark="robotouille", split=split) if c["ablation"] == "original"]
    if not pool_task:
        return f"Per-task table ({split}): no arm without an ablation ran Robotouille {split} tasks."
    tables = []
    models = sorted({c["model_label"] for c in pool_task}, key=test_double_last)
    number = {"synchronous": 5, "asynchronous": 6}[split]
    for model in models:
        mt = [c for c in pool_task if c["model_label"] == model]
        ms = [c for c in pool_split if c["model_label"] == model]
        arms = sorted({(c["method"], c["arm_label"]) for c in mt}, key=lambda a: (method_rank(paper.TASK_ORDER, a[0]), a[1]))
        cols = [Column("task", "task")]
        for _, label in arms:
            cols += rate_columns(label, label)
        notes = Footnotes()
        used: list[Cell] = []
        rows = []
        tasks = sorted({c["task"] for c in mt}, key=lambda t: (paper.task_index(t) is None, paper.task_index(t) or 0, t))
        for task in tasks:
            row: Row = {"task": task}
            idx = paper.task_index(task)
            for c in mt:
                if c["task"] != task:
                    continue
                ref = paper.PER_TASK[split].get(idx, {}).get(c["method"]) if idx is not None else None
                why = paper.mismatch(paper.PROTOCOLS["per_task"], arm_protocol(c), [f"{split}:{idx}"])
                fill_rate(row, c["arm_label"], c, ref, why, notes, paired_p(cells, c, mt, used))
            rows.append(row)
        avg: Row = {"task": "Average"}
        for c in ms:
            ref = paper.PER_TASK_AVERAGE[split].get(c["method"])
            why = paper.mismatch(paper.PROTOCOLS["per_task"], arm_protocol(c))
            fill_rate(avg, c["arm_label"], c, ref, why, notes, paired_p(cells, c, ms, used))
        rows.append(avg)
        m = add_holm(rows, [a[1] for a in arms])
        note = join_notes(
            f"model: {model}. Rows: the benchmark's tasks in order (the paper shows each recipe as a picture); "
            "Average: all episodes of the split pooled (the paper's average of ten equal tasks). Columns: the "
            f"paper's order (ReCAP, ReAct, ADaPT, Act, CoT, Std). p: against ReCAP; {m} comparisons "
            "(Holm over the table).",
            test_notes(mt + ms, used),
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


def _cross_model_pool(cells: Cells) -> list[Cell]:
    """The synchronous 2-4-6 cells of ReAct and ReCAP arms without an ablation at a 64-message window, of the
    models that ran both methods."""
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
    return [c for c in pool if c["model_label"] in both]


def _cross_model_rank(pool: list[Cell], model: str) -> tuple[int, bool, str]:
    """Where ``model``'s columns stand: the paper's column order; a model string the paper does not name is
    placed by its label."""
    order = list(paper.CROSS_MODEL)
    pm = {paper.paper_model(m) for c in pool if c["model_label"] == model for m in c["provider_models"]}
    pm.add(paper.paper_model(model.removesuffix(" (test double)")))
    idx = min((order.index(p) for p in pm if p in order), default=len(order))
    return (idx, *test_double_last(model))


def _cross_model_row(cells: Cells, method: str, label: str, pool: list[Cell], notes: Footnotes, used: list[Cell]) -> Row:
    """One arm's row: its rate per model, beside the paper's for that model and method."""
    row: Row = {"method": label}
    for c in pool:
        if c["arm_label"] != label:
            continue
        proto = arm_protocol(c)
        pm = paper.paper_model(proto.provider_model)
        why = paper.mismatch(paper.PROTOCOLS["cross_model"], proto)
        # a model the paper did not run still gets its footnote (why is then always set)
        ref = paper.CROSS_MODEL.get(pm or "", paper.CROSS_MODEL["gpt-4o"] if why else {}).get(method)
        fill_rate(row, c["model_label"], c, ref, why, notes, paired_p(cells, c, pool, used))
    return row


def cross_model_table(cells: Cells) -> Table | str:
    """Paper Table 2 (ReAct and ReCAP across models on synchronous tasks 2, 4, 6, 64-message window); or the one
    line that says why it is left out."""
    pool = _cross_model_pool(cells)
    if not pool:
        return (
            "Cross-model table: no model has both a ReAct and a ReCAP arm without an ablation on Robotouille "
            "synchronous tasks 2, 4, 6 with a 64-message window."
        )
    models = sorted({c["model_label"] for c in pool}, key=lambda model: _cross_model_rank(pool, model))
    arms = sorted({(c["method"], c["arm_label"]) for c in pool}, key=lambda a: (a[0] != "react", a[1]))
    cols = [Column("method", "method")]
    for model in models:
        cols += rate_columns(model, model)
    notes = Footnotes()
    used: list[Cell] = []
    rows = [_cross_model_row(cells, method, label, pool, notes, used) for method, label in arms]
    m = add_holm(rows, models)
    note = join_notes(
        "Robotouille synchronous tasks 2, 4 and 6, 64-message window. p (on the ReAct rows): against ReCAP of the "
        f"same model on the same units; {m} comparisons (Holm over the table).",
        test_notes(pool, used),
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


def ablation_table(cells: Cells) -> Table | str:
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
        key=lambda k: (*test_double_last(k[0]), k[1]),
    )
    cols = [Column("model", "model"), Column("profile", "profile")]
    for v in variants:
        cols += rate_columns(v, v)
    notes = Footnotes()
    used: list[Cell] = []
    rows = []
    for model, profile in row_keys:
        row: Row = {"model": model, "profile": profile}
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
            fill_rate(row, v, c, paper.ABLATIONS.get(v), why, notes, p)
        rows.append(row)
    m = add_holm(rows, variants)
    note = join_notes(
        "Robotouille synchronous task 6, 128-message window; columns in the paper's order. p: each variant against "
        f"the original (same model and profile) on the units both ran; {m} comparisons (Holm over the table).",
        test_notes(pool, used),
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
