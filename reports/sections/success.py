"""The success section: pass@1 by method and split, per task, per model, per ablation, and paired method tests."""

from __future__ import annotations

from typing import Any

from reports import svg
from reports.model import Column, Plot, Section, Table
from reports.sections.common import (
    PAPER_POINTER,
    Query,
    comparisons_note,
    is_test_double,
    rate_ci,
    row_order,
    series_label,
    slug,
    unique,
)
from reports.stat_notes import interval_note, mcnemar_note, permutation_note, rate_clustered
from reports.stats import clustered_permutation_test, comparisons, holm


def success(q: Query) -> Section:
    """The success section: pass@1 by method and split (table and plot), per task, per model and per ablation,
    and paired tests between methods."""
    sec = Section(
        "success",
        "Success rates",
        "pass@1 over the latest attempt of every unit; cells are success % [95% interval] successes/episodes "
        "(Wilson's; widened by the design effect where an instance ran several seeds: each table's note says which). "
        "Paired tests use units both arms ran (same task, instance and seed) and swap the arms per instance, all its "
        "seeds together.",
    )
    main = q("success_by_split").dicts()
    _main_table(sec, main)
    _main_plot(sec, main)
    _task_tables(sec, q("success_by_task").dicts())
    _model_table(sec, q("success_by_model").dicts())
    _ablation_table(sec, q("success_by_ablation").dicts())
    _paired_table(sec, q("paired_methods").dicts())
    return sec


def _main_table(sec: Section, main: list[dict[str, Any]]) -> None:
    """The main table: success by method and split, one row per model and method."""
    splits = unique(r["env_split"] for r in main)
    keys = sorted(unique((r["model_label"], r["arm"]) for r in main), key=row_order)
    cols = [Column("model", "model"), Column("arm", "method")] + [Column(s, s, "rate_ci") for s in splits]
    rows = []
    for m, a in keys:
        row: dict[str, Any] = {"model": m, "arm": a}
        for r in main:
            if (r["model_label"], r["arm"]) == (m, a):
                row[r["env_split"]] = rate_ci(r)
        rows.append(row)
    sec.tables.append(
        Table(
            "main",
            "Success rate by method and environment split",
            cols,
            rows,
            "success_by_split",
            f"{interval_note(main)} {PAPER_POINTER}".strip(),
        )
    )


def _main_plot(sec: Section, main: list[dict[str, Any]]) -> None:
    """The main table as grouped bars with their intervals."""
    splits = unique(r["env_split"] for r in main)
    models = unique(r["model_label"] for r in main)
    arms = unique(series_label(r["model_label"], r["arm"], models) for r in main)
    values = {(r["env_split"], series_label(r["model_label"], r["arm"], models)): 100 * r["success_rate"] for r in main}
    errors = {
        (r["env_split"], series_label(r["model_label"], r["arm"], models)): (100 * r["ci_low"], 100 * r["ci_high"]) for r in main
    }
    plot_title = "Success rate by environment split (95% Wilson intervals{})".format(
        ", widened by the design effect where an instance ran several seeds" if rate_clustered(main) else ""
    )
    sec.plots.append(
        Plot(
            "success_by_split",
            plot_title,
            svg.grouped_bars(
                plot_title,
                splits,
                arms,
                values,
                errors=errors,
                y_label="success (%)",
                y_max=100,
                value_fmt=lambda v: f"{v:.1f}",
            ),
            "success_by_split",
        )
    )


def _task_tables(sec: Section, per_task: list[dict[str, Any]]) -> None:
    """One table per split: success per task, one column per method (and model)."""
    for s in unique(r["env_split"] for r in per_task):
        rs = [r for r in per_task if r["env_split"] == s]
        split_models = unique(r["model_label"] for r in rs)
        series = unique(series_label(r["model_label"], r["arm"], split_models) for r in rs)
        rows = []
        for task in unique(r["task"] for r in rs):
            row = {"task": task}
            for r in rs:
                if r["task"] == task:
                    row[series_label(r["model_label"], r["arm"], split_models)] = rate_ci(r)
            rows.append(row)
        note = ("model: " + ", ".join(split_models) + ". " if len(split_models) == 1 else "") + interval_note(rs)
        sec.tables.append(
            Table(
                f"tasks_{slug(s)}",
                f"Success rate per task: {s}",
                [Column("task", "task")] + [Column(x, x, "rate_ci") for x in series],
                rows,
                "success_by_task",
                note,
            )
        )


def _model_table(sec: Section, by_model: list[dict[str, Any]]) -> None:
    """The cross-model table: success by model and method over all tasks."""
    arms_m = unique(r["arm"] for r in by_model)
    cols = [Column("model", "model")] + [Column(a, a, "rate_ci") for a in arms_m]
    rows = []
    for m in sorted(unique(r["model_label"] for r in by_model), key=lambda x: (is_test_double(x), x)):
        row = {"model": m}
        for r in by_model:
            if r["model_label"] == m:
                row[r["arm"]] = rate_ci(r)
        rows.append(row)
    sec.tables.append(
        Table(
            "models",
            "Success rate by model (cross-model table, all tasks of the run)",
            cols,
            rows,
            "success_by_model",
            f"{interval_note(by_model)} {PAPER_POINTER}".strip(),
        )
    )


def _ablation_table(sec: Section, abl: list[dict[str, Any]]) -> None:
    """Success by ablation with the paired McNemar test against the original settings (when any ablation ran)."""
    if any(r["ablation"] != "original" for r in abl):
        for r, adj in zip(abl, holm([r["p_value"] for r in abl])):
            r["p_holm"] = adj
            r["rate_ci"] = rate_ci(r)
        sec.tables.append(
            Table(
                "ablations",
                "Success rate by ablation, with a paired McNemar test against the original settings",
                [
                    Column("model_label", "model"),
                    Column("method", "method"),
                    Column("env_split", "split"),
                    Column("window_size", "window", "int"),
                    Column("ablation", "ablation"),
                    Column("rate_ci", "success", "rate_ci"),
                    Column("pairs", "pairs", "int"),
                    Column("original_only", "orig. only", "int"),
                    Column("variant_only", "variant only", "int"),
                    Column("p_value", "p", "p"),
                    Column("p_holm", "Holm p", "p"),
                ],
                abl,
                "success_by_ablation",
                "orig. only / variant only: paired units only one of the two solved. "
                + interval_note(abl)
                + " "
                + mcnemar_note((r["pairs"], r["paired_instances"]) for r in abl if r["pairs"])
                + " "
                + PAPER_POINTER
                + " "
                + comparisons_note(comparisons([r["p_value"] for r in abl]), "McNemar test"),
            )
        )


def _paired_table(sec: Section, paired: list[dict[str, Any]]) -> None:
    """Paired comparisons between methods: discordant pairs, McNemar p and the cost permutation p, Holm-adjusted."""
    for r in paired:
        r["a_rate"] = r["a_successes"] / r["pairs"]
        r["b_rate"] = r["b_successes"] / r["pairs"]
        r["cost_test"] = clustered_permutation_test(r["cost_diffs"], r["cost_instances"])
        r["cost_p"] = r["cost_test"].p
    for key in ("p_value", "cost_p"):
        for r, adj in zip(paired, holm([r[key] for r in paired])):
            r[f"{key}_holm"] = adj
    sec.tables.append(
        Table(
            "paired",
            "Paired comparisons between methods (same units)",
            [
                Column("model_label", "model"),
                Column("env_split", "split"),
                Column("arm_a", "A"),
                Column("arm_b", "B"),
                Column("pairs", "pairs", "int"),
                Column("a_rate", "A %", "pct"),
                Column("b_rate", "B %", "pct"),
                Column("a_only", "A only", "int"),
                Column("b_only", "B only", "int"),
                Column("p_value", "McNemar p", "p"),
                Column("p_value_holm", "Holm p", "p"),
                Column("mean_cost_diff", "mean $ A−B", "usd"),
                Column("cost_p", "cost p (perm.)", "p"),
                Column("cost_p_holm", "Holm cost p", "p"),
            ],
            paired,
            "paired_methods",
            "A only / B only: the discordant pairs. McNemar "
            + mcnemar_note((r["pairs"], r["instances"]) for r in paired)
            + " "
            + permutation_note((r["cost_test"] for r in paired), "cost p (mean cost difference)")
            + " "
            + comparisons_note(comparisons([r["p_value"] for r in paired]), "McNemar test")
            + " "
            + comparisons_note(comparisons([r["cost_p"] for r in paired]), "cost test", "Holm cost p"),
        )
    )
