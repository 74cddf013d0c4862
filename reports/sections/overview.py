"""The overview section: what the report covers, the runs, each arm's coverage, skipped files and events."""

from __future__ import annotations

from typing import Any

from reports.model import Column, Section, Table
from reports.sections.common import Query

#: the overview table's rows: the overview query's columns as the report words them
_COVERS = {
    "run_folders": "run folders",
    "runs": "runs (run ids with episodes)",
    "attempts": "episode rows (attempts)",
    "units": "units with an episode row (one row each: its latest finished attempt, else its latest)",
    "finished_units": "finished units (the rows every success rate counts; the rest: coverage table)",
    "successes": "successes",
    "test_double_units": "units run by a test-double model",
    "llm_calls": "LLM calls (all attempts)",
    "spend_usd": "spend, all LLM calls (USD)",
    "steps": "environment step attempts",
    "skipped_part_files": "unreadable part files skipped",
}


def overview(q: Query) -> Section:
    """The overview section: what the report covers, the runs, each arm's coverage (done, capped, gave up, not
    started), skipped part files and the events summary."""
    sec = Section("overview", "Overview")
    ov = q("overview").dicts()[0]
    rows = [{"metric": _COVERS[k], "value": f"${v:,.4f}" if k == "spend_usd" else f"{v:,}"} for k, v in ov.items()]
    sec.tables.append(
        Table("overview", "What this report covers", [Column("metric", "metric"), Column("value", "value")], rows, "overview")
    )
    sec.tables.append(
        Table(
            "runs",
            "Runs",
            [
                Column("run_id", "run"),
                Column("starts", "starts", "int"),
                Column("first_started", "first started"),
                Column("host", "host"),
                Column("git_revision", "git revision"),
                Column("spec_hash", "spec hash"),
                Column("units", "units", "int"),
                Column("successes", "successes", "int"),
            ],
            q("runs").dicts(),
            "runs",
        )
    )
    coverage = q("coverage").dicts()
    if coverage:
        sec.tables.append(_coverage_table(coverage))
    skipped = q("skipped_parts").dicts()
    if skipped:
        sec.tables.append(
            Table(
                "skipped_parts",
                "Skipped part files (unreadable; their rows are not in any table)",
                [Column("table", "table"), Column("path", "file"), Column("error", "error")],
                skipped,
                "skipped_parts",
            )
        )
    events = q("events_summary").dicts()
    if events:
        sec.tables.append(
            Table(
                "events",
                "Pipeline events",
                [
                    Column("source", "source"),
                    Column("kind", "kind"),
                    Column("severity", "severity"),
                    Column("events", "events", "int"),
                    Column("episodes", "episodes", "int"),
                ],
                events,
                "events_summary",
            )
        )
    return sec


def _coverage_table(coverage: list[dict[str, Any]]) -> Table:
    """Planned and finished units per arm, with a note on where ``planned`` came from."""
    derived = sorted({r["run_id"] or "?" for r in coverage if r["planned_from"] != "plan.json"})
    note = (
        "finished: the units every success rate counts (they finished on their own merits; env_error and "
        "llm_error outcomes count). capped: the latest attempt ended budget_exhausted (a cap stopped it); "
        "gave up: the latest attempt ended in an infrastructure failure (infra_error: the model service failed or "
        "the workers died; recap resume retries it); not started: no episode row. The same counts as recap status."
    )
    if derived:
        note += (
            f" No readable plan.json for run {', '.join(derived)}: planned is derived from the episode rows "
            "(units never started are not counted)."
        )
    return Table(
        "coverage",
        "Coverage: planned and finished units per arm",
        [
            Column("run_id", "run"),
            Column("model_label", "model"),
            Column("arm", "arm"),
            Column("planned", "planned", "int"),
            Column("finished", "finished", "int"),
            Column("successes", "successes", "int"),
            Column("capped", "capped", "int"),
            Column("gave_up", "gave up", "int"),
            Column("not_started", "not started", "int"),
            Column("planned_from", "planned from"),
        ],
        coverage,
        "coverage",
        note,
    )
