"""The failure-mode section: how episodes ended, by the mode the report assigns each failure."""

from __future__ import annotations

from typing import Any

from reports import svg
from reports.model import Column, Plot, Section, Table
from reports.sections.common import Query, row_order, series_label, unique

MODE_NOTE = (
    "One mode per episode, first match wins: success; model_error:<kind> (LLM error, kind of the "
    "last failed call); for a coding episode whose submission was judged not resolved, the "
    "evaluation's reason (tests_failed, patch_failed, patch_refused, no_patch, timeout), "
    "autosubmitted:<reason> when a limit handed the diff in; json_failures, truncated (a reply cut "
    "at the output cap), budget_exhausted, episode_limit, env_error; then for step "
    "cap, call cap and agent-declared done: invalid_action_loop (>= 3 invalid attempts in a row, "
    "or one invalid action tried >= 3 times), repeated_action_loop (a cycle of 1-3 identical "
    "(action, observation) steps repeated >= 3 times back to back over >= 4 steps); then "
    "agent_done_early, step_cap, call_cap; other:<end_reason> for anything else."
)


def failures(q: Query) -> Section:
    """The failure-mode section: one mode per episode (first match wins, see MODE_NOTE) with cost and example
    episodes, overall and by method."""
    sec = Section("failures", "Failure modes", MODE_NOTE)
    rows = q("failure_modes").dicts()
    for r in rows:
        r["examples"] = list(r["examples"])
    t = Table(
        "failure_modes",
        "Failure modes: episodes, cost and examples",
        [
            Column("model_label", "model"),
            Column("mode", "mode"),
            Column("episodes", "episodes", "int"),
            Column("share", "share %", "pct"),
            Column("cost_usd", "cost", "usd"),
            Column("mean_steps", "steps/episode", "float"),
            Column("mean_calls", "calls/episode", "float"),
            Column("examples", "example episodes", "list"),
        ],
        rows,
        "failure_modes",
    )
    sec.tables.append(t)
    by_arm = q("failure_modes_by_arm").dicts()
    modes = sorted(unique(r["mode"] for r in by_arm), key=lambda m: (m != "success", m))
    keys = sorted(unique((r["model_label"], r["arm"]) for r in by_arm), key=row_order)
    rows2 = []
    for m, a in keys:
        row: dict[str, Any] = {"model": m, "arm": a}
        for r in by_arm:
            if (r["model_label"], r["arm"]) == (m, a):
                row[r["mode"]] = r["episodes"]
        rows2.append(row)
    sec.tables.append(
        Table(
            "failure_modes_by_arm",
            "Failure modes by method (episodes)",
            [Column("model", "model"), Column("arm", "method")] + [Column(mo, mo, "int") for mo in modes],
            rows2,
            "failure_modes_by_arm",
        )
    )
    models = unique(m for m, _ in keys)
    cats = [series_label(m, a, models) for m, a in keys]
    counts = {(series_label(r["model_label"], r["arm"], models), r["mode"]): float(r["episodes"]) for r in by_arm}
    sec.plots.append(
        Plot(
            "failure_modes",
            "Failure modes by method",
            svg.stacked_shares("Failure modes by method", cats, modes, counts),
            "failure_modes_by_arm",
        )
    )
    return sec
