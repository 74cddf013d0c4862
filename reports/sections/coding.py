"""The coding section: SWE-bench runs' tool calls, cost, resolve rate by tool calls, and how episodes failed.

Why a section of its own: a coding episode's story is its tool calls and its evaluation (the
``evaluations`` table: resolved, no_patch, patch_failed, tests_failed, timeout; our evaluator's and
the official harness's verdicts), which no other benchmark has. The two plots are the paper's
SWE-bench figures ("tool call and cost distributions", "task resolve rate by number of tool calls"),
drawn per method. A run without coding episodes (benchmarks ``swe``, ``swe-verified``) gets no such
section and none of its queries' CSV files, so its report is what it was.
"""

from __future__ import annotations

from typing import Any

from reports import svg
from reports.model import Column, Plot, Section, Table
from reports.sections.common import Query, is_test_double, unique
from reports.views import Result

#: the evaluations table's reasons, in the order the failure table shows them (all five, always)
REASONS = ("resolved", "tests_failed", "patch_failed", "no_patch", "timeout")
#: the queries the section runs (each kept for the CSV output only when the run has coding episodes)
QUERIES = ("coding_outcomes", "coding_grading", "coding_distribution", "coding_episodes", "coding_resolve_by_calls")

INTRO = (
    "Coding episodes (SWE-bench: benchmarks swe and swe-verified). Tool calls are the episode's tool_calls rows "
    "(a model's tool calls, or a text-action agent's shell commands; valid or not). The plots are the paper's two "
    "SWE-bench figures, per method: tool calls against cost per episode (a filled dot resolved its issue, a ring "
    "did not), and the resolved share by number of tool calls (95% Wilson intervals, episodes taken as "
    "independent). Plots and distributions count the units that finished on their own merits; the outcome table "
    "counts every unit's row, capped ones included."
)


def _key(r: dict[str, Any]) -> tuple[str, str, str]:
    return (r["model_label"], r["arm"], r["benchmark"])


def _order(k: tuple[str, str, str]) -> tuple[str, bool, str, str]:
    """Rows: by benchmark, real models before test doubles, then model and arm."""
    return (k[2], is_test_double(k[0]), k[0], k[1])


def _series_names(keys: list[tuple[str, str, str]]) -> dict[tuple[str, str, str], str]:
    """A plot series per (model, arm, benchmark): the arm, with the model and the benchmark when the report
    holds several of them."""
    several_models = len(unique(k[0] for k in keys)) > 1
    several_benches = len(unique(k[2] for k in keys)) > 1
    return {k: " · ".join([k[1]] + ([k[0]] if several_models else []) + ([k[2]] if several_benches else [])) for k in keys}


def _outcome_table(rows: list[dict[str, Any]]) -> Table:
    extra = sorted(unique(r["outcome"] for r in rows if r["outcome"] not in REASONS))
    out: list[dict[str, Any]] = []
    for k in sorted(unique(_key(r) for r in rows), key=_order):
        row: dict[str, Any] = {"model": k[0], "arm": k[1], "benchmark": k[2], "episodes": 0, "cost_usd": 0.0}
        row.update(dict.fromkeys(REASONS + tuple(extra), 0))
        for r in rows:
            if _key(r) == k:
                row[r["outcome"]] = r["episodes"]
                row["episodes"] += r["episodes"]
                row["cost_usd"] += r["cost_usd"] or 0.0
        out.append(row)
    return Table(
        "coding_outcomes",
        "Coding episodes: how each ended (evaluation reason, or why it was never evaluated)",
        [
            Column("model", "model"),
            Column("arm", "method"),
            Column("benchmark", "benchmark"),
            Column("episodes", "episodes", "int"),
        ]
        + [Column(o, o, "int") for o in REASONS + tuple(extra)]
        + [Column("cost_usd", "cost", "usd")],
        out,
        "coding_outcomes",
        "resolved / tests_failed / patch_failed / no_patch / timeout: the evaluations table's reason (the deciding "
        "grader's verdict). no evaluation: <end_reason>: the episode ended before it submitted (a model error, JSON "
        "failures, the budget) and was never evaluated; an exhausted step limit submits and is evaluated.",
    )


def _grading_table(rows: list[dict[str, Any]]) -> Table:
    rows = sorted(rows, key=lambda r: _order(_key(r)))
    both = sum(r["official_graded"] for r in rows)
    differ = sum(r["disagreements"] for r in rows)
    line = (
        f"Ours and the official harness disagree on {differ} of the {both} episodes both graded."
        if both
        else "The official harness graded no episode (grading ours, or no swebench package): nothing to compare."
    )
    shown = [{**r, "model": r["model_label"], "disagreeing": list(r["disagreeing"])} for r in rows]
    return Table(
        "coding_grading",
        "Coding episodes: our evaluator against the official SWE-bench harness",
        [
            Column("model", "model"),
            Column("arm", "method"),
            Column("benchmark", "benchmark"),
            Column("judged", "evaluated", "int"),
            Column("official_graded", "official graded", "int"),
            Column("ours_resolved", "ours resolved", "int"),
            Column("official_resolved", "official resolved", "int"),
            Column("disagreements", "disagree", "int"),
            Column("ours_only", "ours only", "int"),
            Column("official_only", "official only", "int"),
            Column("disagreeing", "disagreeing instances", "list"),
        ],
        shown,
        "coding_grading",
        line + " ours only: we resolved it, the harness did not; official only: the other way round.",
    )


def _distribution_table(rows: list[dict[str, Any]]) -> Table:
    rows = sorted(rows, key=lambda r: _order(_key(r)))
    return Table(
        "coding_distribution",
        "Coding episodes: tool calls and cost per episode",
        [
            Column("model_label", "model"),
            Column("arm", "method"),
            Column("benchmark", "benchmark"),
            Column("episodes", "episodes", "int"),
            Column("resolved", "resolved", "int"),
            Column("calls_mean", "calls mean", "float"),
            Column("calls_median", "calls median", "float"),
            Column("calls_p90", "calls p90", "float"),
            Column("calls_max", "calls max", "int"),
            Column("cost_mean", "cost mean", "usd"),
            Column("cost_median", "cost median", "usd"),
            Column("cost_p90", "cost p90", "usd"),
            Column("cost_max", "cost max", "usd"),
        ],
        rows,
        "coding_distribution",
    )


def _by_calls(rows: list[dict[str, Any]], names: dict[tuple[str, str, str], str]) -> tuple[Table, Plot]:
    bins = [b for _, b in sorted(unique((r["bin_low"], r["bin"]) for r in rows))]
    series = [names[k] for k in sorted(names, key=_order)]
    table_rows = []
    values: dict[tuple[str, str], float] = {}
    errors: dict[tuple[str, str], tuple[float, float]] = {}
    for b in bins:
        row: dict[str, Any] = {"bin": b}
        for r in rows:
            if r["bin"] == b:
                s = names[_key(r)]
                row[s] = (r["resolved"], r["episodes"], r["ci_low"], r["ci_high"])
                values[(b, s)] = 100.0 * r["resolve_rate"]
                errors[(b, s)] = (100.0 * r["ci_low"], 100.0 * r["ci_high"])
        table_rows.append(row)
    table = Table(
        "coding_resolve_by_calls",
        "Coding episodes: resolved % [95% interval] resolved/episodes by number of tool calls",
        [Column("bin", "tool calls")] + [Column(s, s, "rate_ci") for s in series],
        table_rows,
        "coding_resolve_by_calls",
    )
    plot = Plot(
        "coding_resolve_by_calls",
        "Resolve rate by number of tool calls",
        svg.grouped_bars(
            "Resolve rate by number of tool calls",
            bins,
            series,
            values,
            errors=errors,
            y_label="resolved (%)",
            y_max=100.0,
            value_fmt=lambda v: f"{v:.1f}",
        ),
        "coding_resolve_by_calls",
    )
    return table, plot


def coding(q: Query, results: dict[str, Result]) -> Section | None:
    """The section, or None when the run has no coding unit (its probe query is then dropped from
    ``results``, so no CSV file appears)."""
    outcomes = q("coding_outcomes").dicts()
    if not outcomes:
        results.pop("coding_outcomes", None)
        return None
    sec = Section("coding", "Coding (SWE-bench)", INTRO)
    sec.tables.append(_outcome_table(outcomes))
    sec.tables.append(_grading_table(q("coding_grading").dicts()))
    sec.tables.append(_distribution_table(q("coding_distribution").dicts()))
    episodes = q("coding_episodes").dicts()
    names = _series_names(sorted(unique(_key(r) for r in episodes), key=_order))
    points: dict[str, list[tuple[float, float, bool]]] = {names[k]: [] for k in sorted(names, key=_order)}
    for r in episodes:
        points[names[_key(r)]].append((float(r["tool_calls"]), float(r["cost_usd"]), bool(r["resolved"])))
    sec.plots.append(
        Plot(
            "coding_calls_cost",
            "Tool calls and cost per episode",
            svg.scatter(
                "Tool calls and cost per episode",
                points,
                x_label="tool calls per episode",
                y_label="cost per episode (USD)",
                y_fmt=lambda v: f"${v:,.2f}",
            ),
            "coding_episodes",
        )
    )
    table, plot = _by_calls(q("coding_resolve_by_calls").dicts(), names)
    sec.tables.append(table)
    sec.plots.append(plot)
    return sec
