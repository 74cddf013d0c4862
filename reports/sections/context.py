"""The context-bound section: prompt tokens by call index, and how fast prompts still grow once the window is full."""

from __future__ import annotations

from reports import svg
from reports.model import Column, Plot, Section, Table
from reports.sections.common import Query, series_label, unique


def context(q: Query) -> Section:
    """The context-bound section: mean prompt tokens by call index (plot) and how fast prompts still grow once
    the window is full."""
    sec = Section(
        "context",
        "The context bound",
        "Prompt tokens of each call by its position in the episode (successful calls of latest "
        "attempts). A bounded window keeps the curve flat once it is full. Growth after the window "
        "fills, per episode: the least-squares slope of prompt tokens over the calls from the first "
        "call with the episode's largest window on (when that window reached the arm's window size), "
        "summarised over those episodes as median [25th, 75th percentile] tokens per call.",
    )
    per_call = q("context_by_call").dicts()
    models = unique(r["model_label"] for r in per_call)
    series: dict[str, list[tuple[float, float]]] = {}
    for r in per_call:
        series.setdefault(series_label(r["model_label"], r["arm"], models), []).append(
            (float(r["call_index"]), float(r["mean_prompt_tokens"]))
        )
    sec.plots.append(
        Plot(
            "context_by_call",
            "Mean prompt tokens by call index",
            svg.lines("Mean prompt tokens by call index", series, x_label="call index in the episode", y_label="prompt tokens"),
            "context_by_call",
        )
    )
    sec.tables.append(
        Table(
            "context",
            "Prompt tokens per call",
            [
                Column("model_label", "model"),
                Column("arm", "method"),
                Column("calls", "calls", "int"),
                Column("mean_prompt_tokens", "mean", "tokens"),
                Column("median_prompt_tokens", "median", "tokens"),
                Column("p95_prompt_tokens", "p95", "tokens"),
                Column("max_prompt_tokens", "max", "int"),
                Column("max_window_messages", "max window (messages)", "int"),
                Column("episodes", "episodes", "int"),
                Column("filled_episodes", "window filled", "int"),
                Column("slope_median", "growth after fill: median (tokens/call)", "float"),
                Column("slope_q25", "25th pct.", "float"),
                Column("slope_q75", "75th pct.", "float"),
            ],
            q("context_summary").dicts(),
            "context_summary",
        )
    )
    return sec
