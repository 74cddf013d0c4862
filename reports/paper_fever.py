"""The paper section's FEVER breakdown: pass@1 per claim label (SUPPORTS, REFUTES, NOT ENOUGH INFO).

Why a table of its own: FEVER's one main-table number hides how the verdicts split - a method that
answers NOT ENOUGH INFO whenever a search fails scores on that label and nowhere else. The FEVER
environment reports each claim's label as the episode's task (the claim's label never reaches the
prompt), so the label cells are the task-level cells of ``fever/dev``. The paper reports no number
per label; its overall number (Table 1) stands in the "All claims" row when the arm ran its protocol.
"""

from __future__ import annotations

import re
from typing import Any

from reports import paper
from reports.model import Column, Table
from reports.paper_cells import (
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

ALL_ROW = "All claims"


def _label_key(label: str) -> tuple[int, str]:
    """The paper's label order, anything else after it."""
    return (paper.FEVER_LABELS.index(label) if label in paper.FEVER_LABELS else len(paper.FEVER_LABELS), label)


def fever_label_tables(cells: Cells) -> list[Table] | str:
    """One table per model: a row per label, then all claims pooled; or the one line that says why it is left out."""
    pool_label = [c for c in cells.select(level="task", benchmark="fever") if c["ablation"] == "original"]
    pool_all = [c for c in cells.select(level="split", benchmark="fever") if c["ablation"] == "original"]
    if not pool_label:
        return "FEVER by label: no arm without an ablation ran FEVER claims."
    tables = []
    for model in sorted({c["model_label"] for c in pool_label}, key=test_double_last):
        by_label = [c for c in pool_label if c["model_label"] == model]
        overall = [c for c in pool_all if c["model_label"] == model]
        arms = sorted(
            {(c["method"], c["arm_label"]) for c in by_label}, key=lambda a: (method_rank(paper.MAIN_ORDER, a[0]), a[1])
        )
        cols = [Column("label", "label")]
        for _, arm in arms:
            cols += rate_columns(arm, arm)
        notes = Footnotes()
        used: list[dict[str, Any]] = []
        rows: list[dict[str, Any]] = []
        for label in sorted({c["task"] for c in by_label}, key=_label_key):
            row: dict[str, Any] = {"label": label}
            for c in by_label:
                if c["task"] == label:
                    fill_rate(row, c["arm_label"], c, None, None, notes, paired_p(cells, c, by_label, used))
            rows.append(row)
        total: dict[str, Any] = {"label": ALL_ROW}
        for c in overall:
            ref = paper.main_reference("fever", c["method"])
            why = paper.mismatch(paper.PROTOCOLS["main"], arm_protocol(c))
            fill_rate(total, c["arm_label"], c, ref, why, notes, paired_p(cells, c, overall, used))
        rows.append(total)
        m = add_holm(rows, [a[1] for a in arms])
        note = join_notes(
            f"model: {model}. Rows: the claims' gold labels (the paper reports no number per label), then every "
            f"claim pooled beside the paper's Table 1 FEVER number. p: against ReCAP; {m} comparisons (Holm over the table).",
            test_notes(by_label + overall, used),
            notes.text(),
        )
        slug = re.sub(r"[^0-9A-Za-z]+", "_", model).strip("_")
        tables.append(Table(f"paper_fever_labels_{slug}", "FEVER: pass@1 (%) per claim label", cols, rows, "paper_cells", note))
    return tables
