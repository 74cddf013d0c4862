"""The costs section: calls, tokens and dollars per episode and per success, spend per model, wasted spend."""

from __future__ import annotations

from typing import Any

from reports import paper, svg
from reports.model import Column, Plot, Section, Table
from reports.sections.common import Query, series_label, unique


def costs(q: Query) -> Section:
    """The costs section: calls, tokens and dollars per episode and per success, spend per model, and the spend
    of attempts that did not count."""
    c = paper.COSTS["robotouille_sync_task6"]
    sec = Section(
        "costs",
        "Costs",
        "Per episode and per success over the latest attempts (episode rows); spend tables count "
        f"every LLM call of every attempt. Paper anchors: Robotouille sync task 6 {c['calls_per_episode']} "
        f"calls (sd {c['calls_sd']}) and ${c['usd_per_episode']} (sd {c['usd_sd']}) per episode; ALFWorld "
        f"134 games ${paper.COSTS['alfworld_134_games_usd']['recap']} ReCAP vs ${paper.COSTS['alfworld_134_games_usd']['react']} ReAct.",
    )
    rows = q("costs").dicts()
    _costs_table(sec, rows)
    _cost_plot(sec, rows)
    _spend_tables(sec, q)
    return sec


def _costs_table(sec: Section, rows: list[dict[str, Any]]) -> None:
    """Dollars, tokens and calls per episode and per success, per model, method and split."""
    sec.tables.append(
        Table(
            "costs",
            "Dollars, tokens and calls per episode and per success",
            [
                Column("model_label", "model"),
                Column("arm", "method"),
                Column("env_split", "split"),
                Column("episodes", "episodes", "int"),
                Column("successes", "successes", "int"),
                Column("cost_per_episode", "$/episode", "usd"),
                Column("cost_sd", "sd", "usd"),
                Column("cost_per_success", "$/success", "usd"),
                Column("tokens_per_episode", "tokens/episode", "tokens"),
                Column("tokens_per_success", "tokens/success", "tokens"),
                Column("calls_per_episode", "calls/episode", "float"),
                Column("calls_sd", "sd", "float"),
                Column("cached_share", "cached %", "pct"),
                Column("steps_per_episode", "steps/episode", "float"),
                Column("cost_usd", "total $", "usd"),
            ],
            rows,
            "costs",
        )
    )


def _cost_plot(sec: Section, rows: list[dict[str, Any]]) -> None:
    """Dollars per episode as grouped bars by split."""
    splits = unique(r["env_split"] for r in rows)
    models = unique(r["model_label"] for r in rows)
    series = unique(series_label(r["model_label"], r["arm"], models) for r in rows)
    values = {(r["env_split"], series_label(r["model_label"], r["arm"], models)): r["cost_per_episode"] for r in rows}
    sec.plots.append(
        Plot(
            "cost_per_episode",
            "Dollars per episode",
            svg.grouped_bars(
                "Dollars per episode", splits, series, values, y_label="USD per episode", value_fmt=lambda v: f"${v:,.4f}"
            ),
            "costs",
        )
    )


def _spend_tables(sec: Section, q: Query) -> None:
    """Spend by model, and the spend that bought no success (every call of every attempt)."""
    sec.tables.append(
        Table(
            "spend_by_model",
            "Spend by model (every call of every attempt)",
            [
                Column("model_label", "model"),
                Column("calls", "calls", "int"),
                Column("failed_calls", "failed", "int"),
                Column("retries", "retries", "int"),
                Column("prompt_tokens", "prompt tokens", "int"),
                Column("cached_share", "cached %", "pct"),
                Column("completion_tokens", "completion tokens", "int"),
                Column("cost_usd", "spend", "usd"),
                Column("spend_share", "share %", "pct"),
            ],
            q("spend_by_model").dicts(),
            "spend_by_model",
        )
    )
    sec.tables.append(
        Table(
            "wasted_spend",
            "Spend that bought no success",
            [
                Column("model_label", "model"),
                Column("arm", "method"),
                Column("cost_usd", "spend", "usd"),
                Column("failed_calls", "failed calls", "int"),
                Column("retries", "retries", "int"),
                Column("failed_call_cost", "failed-call $", "usd"),
                Column("repair_calls", "JSON repairs", "int"),
                Column("repair_cost", "repair $", "usd"),
                Column("superseded_cost", "re-run attempts $", "usd"),
                Column("orphan_cost", "lost attempts $", "usd"),
                Column("failed_episode_cost", "failed episodes $", "usd"),
                Column("wasted_cost", "wasted $", "usd"),
                Column("wasted_share", "wasted %", "pct"),
            ],
            q("wasted_spend").dicts(),
            "wasted_spend",
            "wasted = all spend except the calls of successful latest attempts (= re-run + lost + failed episodes). "
            "Failed-call and repair spend are shown separately and are part of whichever episode they belong to.",
        )
    )
