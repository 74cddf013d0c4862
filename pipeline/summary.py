"""What a run folder holds, as numbers and a table: the end-of-run summary and ``recap status``.

Both read only the run folder (plan.json + the tables), so they work after a crash, while a run
is still going, and on a folder copied from a cluster. Unreadable part files are counted and
named, never fatal; so is a torn or corrupt line of the gateway's ledger journal (one line:
which file, which line, what to do).

A unit is *done* (finished on its own merits) when it has a terminal row that is neither
``budget_exhausted`` nor an infrastructure failure (:func:`pipeline.resume.infra_failure`: end
reason ``infra_error``); units whose latest row is an infrastructure failure *gave up* and are
counted apart, with the command that retries them. Success rates count done units only.

Per arm (the arm's label x model) the table says what was planned and where each planned unit
stands: done, stopped by a cap (its latest row ``budget_exhausted``), gave up (infrastructure),
not started - a run that a cap stopped early shows at a glance which arms were sampled. The
report's coverage table (``reports/sql/coverage.sql``) applies the same rules and gives the same
numbers for the same run. Units that ended ``env_error``/``llm_error`` count as done; the line
under the table says how many and that ``recap resume RUN --retry errors`` runs them again.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any

import pyarrow as pa
from rich.markup import escape

from pipeline.resume import ERROR_END_REASONS, infra_failure, journal_issue, run_spend
from pipeline.store import PLAN_FILE, RunStore
from pipeline.tables import Col, print_fitted
from recap.plural import count
from schemas.parts import BadPart, inspect_parts, read_parts

TEST_DOUBLE_LABEL = " (test double)"


@dataclass
class GroupRow:
    """One line of the status table: an arm (label x model) and where its planned units stand (done, stopped by a
    cap, gave up, not started)."""

    #: the arm's label (plan.json's "method")
    method: str
    model: str
    units: int
    done: int = 0
    success: int = 0
    budget_stopped: int = 0
    failed: int = 0
    steps: int = 0
    calls: int = 0
    cost_usd: float = 0.0
    test_double: bool = False
    #: done units whose completing row ended env_error / llm_error (``--retry errors`` re-runs them)
    errored: int = 0

    @property
    def planned(self) -> int:
        """Units the plan holds for this arm (the table's "planned" column)."""
        return self.units

    @property
    def not_started(self) -> int:
        """Planned units without any terminal row."""
        return self.units - self.done - self.budget_stopped - self.failed


@dataclass
class StatusReport:
    """What ``recap status`` and the end-of-run summary show: totals, the per-arm rows, and every unreadable part
    or journal problem found on the way."""

    location: str
    run: str
    run_id: str
    total: int
    completed: int
    success: int
    budget_stopped: int
    spend_usd: float
    terminal_rows: int
    duplicate_terminal: int
    groups: list[GroupRow] = field(default_factory=list)
    bad_parts: list[BadPart] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    #: units whose latest terminal row is an infrastructure failure (retryable), by kind
    failed: int = 0
    failed_kinds: dict[str, int] = field(default_factory=dict)
    #: done units whose completing row ended env_error / llm_error (not infrastructure)
    errored: int = 0
    #: reservations still open in the ledger journal (calls in flight, or orphans of a crash)
    reserved_usd: float = 0.0

    @property
    def spend_line(self) -> str:
        """The run's spend as every line prints it (``spend_usd``: the ledger journal's)."""
        reserved = f" (+ ${self.reserved_usd:.4f} reserved by calls in flight)" if self.reserved_usd > 0 else ""
        return f"${self.spend_usd:.4f}{reserved}"

    @property
    def remaining(self) -> int:
        """Planned units not yet done (stopped by a cap, gave up, or not started)."""
        return self.total - self.completed

    def errors_hint(self) -> str | None:
        """One line on the units ``--retry errors`` would run again, or None."""
        if not self.errored:
            return None
        return (
            f"{self.errored} done units ended in env_error or llm_error; once the cause is fixed, "
            f"run them again with: recap resume {self.location} --retry errors"
        )

    def retry_hint(self) -> str | None:
        """One line on the units that gave up in an infrastructure failure and the command that retries them, or None."""
        if not self.failed:
            return None
        kinds = ", ".join(f"{k} {n}" for k, n in sorted(self.failed_kinds.items()))
        return (
            f"{count(self.failed, 'unit')} ended in an infrastructure failure ({kinds}); fix the cause, "
            f"then retry them with: recap resume {self.location}"
        )


def model_label(name: str, test_double: bool) -> str:
    """The model's name as the tables show it: test doubles marked, so their nominal spend is not read as money."""
    return name + (TEST_DOUBLE_LABEL if test_double else "")


def _read_plan_units(store: RunStore, problems: list[str]) -> list[dict[str, Any]]:
    """The plan's units (none, and a problem named, when plan.json cannot be read)."""
    try:
        plan = store.read_json(PLAN_FILE) or {"units": []}
    except ValueError as exc:
        plan = {"units": []}
        problems.append(f"{PLAN_FILE} unreadable: {exc}")
    units: list[dict[str, Any]] = plan.get("units", [])
    return units


def _latest_rows(rows: list[dict[str, Any]]) -> tuple[dict[str, dict[str, Any]], dict[str, dict[str, Any]], int]:
    """Per unit its latest terminal row and its latest row that completes it; and how many
    terminal rows repeat a (unit, attempt) already written."""
    latest: dict[str, dict[str, Any]] = {}
    final: dict[str, dict[str, Any]] = {}  # the latest row that completes its unit
    seen: dict[tuple[str, int], int] = defaultdict(int)
    for r in rows:
        seen[(r["unit_id"], r["attempt"])] += 1
        prev = latest.get(r["unit_id"])
        if prev is None or r["attempt"] > prev["attempt"]:
            latest[r["unit_id"]] = r
        if r["end_reason"] != "budget_exhausted" and infra_failure(r["end_reason"], r["error"]) is None:
            prev = final.get(r["unit_id"])
            if prev is None or r["attempt"] > prev["attempt"]:
                final[r["unit_id"]] = r
    duplicates = sum(n - 1 for n in seen.values() if n > 1)
    return latest, final, duplicates


def _journal_problems(store: RunStore, problems: list[str]) -> None:
    """A damaged or unsplittable ledger journal, named among the problems (never raised)."""
    try:
        issue = journal_issue(store)
    except Exception as exc:  # status never dies on a damaged folder
        problems.append(f"ledger journal unreadable: {type(exc).__name__}: {exc}".splitlines()[0])
    else:
        if issue is not None:
            problems.append(issue.describe().replace("<run>", store.location))


def _spend(store: RunStore, calls: pa.Table, rows: list[dict[str, Any]]) -> tuple[float, float]:
    """(spent, reserved) USD. One figure for spend: the ledger journal's (worst-case charges of
    calls that have no llm_calls row of their own - cut, orphaned - included); the rows only
    without a journal."""
    ledger = run_spend(store)
    if ledger is not None:
        return ledger.spent_usd, ledger.reserved_usd
    if calls.num_rows:
        return float(sum(c or 0.0 for c in calls.column("cost_usd").to_pylist())), 0.0
    return float(sum(r["cost_usd"] for r in rows)), 0.0


def _group_rows(
    units: list[dict[str, Any]], latest: dict[str, dict[str, Any]], final: dict[str, dict[str, Any]]
) -> tuple[dict[tuple[str, str], GroupRow], dict[str, int]]:
    """One row per (method, model) from each unit's deciding terminal row; failures by kind."""
    failed_kinds: dict[str, int] = defaultdict(int)
    groups: dict[tuple[str, str], GroupRow] = {}
    for u in units:
        key = (u["method"], u["model"])
        g = groups.setdefault(key, GroupRow(u["method"], u["model"], 0, test_double=u["model"].startswith("offline/")))
        g.units += 1
        r = final.get(u["unit_id"]) or latest.get(u["unit_id"])
        if r is None:
            continue
        g.test_double = g.test_double or bool(r["test_double"])
        g.cost_usd += r["cost_usd"]
        if r["end_reason"] == "budget_exhausted":
            g.budget_stopped += 1
            continue
        kind = infra_failure(r["end_reason"], r["error"])
        if kind is not None:
            g.failed += 1
            failed_kinds[kind] += 1
            continue
        g.done += 1
        g.errored += int(r["end_reason"] in ERROR_END_REASONS)
        g.success += int(r["success"])
        g.steps += r["steps"]
        g.calls += r["llm_calls"]
    return groups, dict(failed_kinds)


def collect(store: RunStore) -> StatusReport:
    """Read plan + tables and count; never raises for unreadable parts (they are listed)."""
    ident = store.require_identity()
    problems: list[str] = []
    units = _read_plan_units(store, problems)
    bad: list[BadPart] = []
    # one rule with recap sql / recap report: a part without the table's exact columns and
    # types is skipped and named (schemas.parts.schema_problem), never cast and counted
    opener = store.fs.open_input_file if store.remote else None
    eps, b = read_parts(store.part_files("episodes"), "episodes", open_file=opener)
    bad += b
    rows = eps.to_pylist()
    latest, final, duplicates = _latest_rows(rows)
    calls, b = read_parts(store.part_files("llm_calls"), "llm_calls", ["cost_usd"], open_file=opener)
    bad += b
    for table in store.tables():  # the other tables: status names every unreadable part
        if table not in ("episodes", "llm_calls"):
            bad += inspect_parts(store.part_files(table), table, opener)[1]
    _journal_problems(store, problems)
    spend, reserved = _spend(store, calls, rows)
    groups, failed_kinds = _group_rows(units, latest, final)
    return StatusReport(
        location=store.location,
        run=ident.run,
        run_id=ident.run_id,
        total=len(units),
        completed=sum(g.done for g in groups.values()),
        success=sum(g.success for g in groups.values()),
        budget_stopped=sum(g.budget_stopped for g in groups.values()),
        spend_usd=spend,
        terminal_rows=len(rows),
        duplicate_terminal=duplicates,
        groups=list(groups.values()),
        bad_parts=bad,
        problems=problems,
        failed=sum(g.failed for g in groups.values()),
        failed_kinds=failed_kinds,
        errored=sum(g.errored for g in groups.values()),
        reserved_usd=reserved,
    )


def render(report: StatusReport, console: Any) -> None:
    """The summary table plus totals (rich)."""
    # left out first when the terminal is narrow: the rarer counts, then the averages (the arm,
    # its model, done and success stay)
    cols = (
        Col("arm", "left"),
        Col("model", "left"),
        Col("planned", drop=6),
        Col("done", drop=9),
        Col("success", drop=10),
        Col("capped", drop=2),
        Col("gave up", drop=3),
        Col("not started", drop=5),
        Col("avg steps", drop=1),
        Col("avg calls", drop=4),
        Col("cost $", drop=8),
    )
    rows = []
    for g in report.groups:
        rate = f"{g.success}/{g.done} ({100 * g.success / g.done:.0f}%)" if g.done else "-"
        rows.append(
            [
                g.method,
                model_label(g.model, g.test_double),
                str(g.planned),
                str(g.done),
                rate,
                str(g.budget_stopped),
                str(g.failed),
                str(g.not_started),
                f"{g.steps / g.done:.1f}" if g.done else "-",
                f"{g.calls / g.done:.1f}" if g.done else "-",
                f"{g.cost_usd:.4f}",
            ]
        )
    print_fitted(console, f"run {report.run} ({report.run_id}) - {report.location}", cols, rows)
    failed = f"{report.failed} failed on infrastructure, " if report.failed else ""
    console.print(
        f"units {report.completed}/{report.total} done, {report.success} succeeded, "
        f"{report.budget_stopped} stopped by a budget cap, {failed}"
        f"{report.remaining - report.budget_stopped - report.failed} not finished; "
        f"spend {report.spend_line}"
    )
    hint = report.retry_hint()
    if hint:
        console.print(hint, style="red", markup=False, soft_wrap=True)
    errors = report.errors_hint()
    if errors:
        console.print(errors, markup=False, soft_wrap=True)
    if report.duplicate_terminal:
        console.print(f"[red]{report.duplicate_terminal} duplicate terminal rows[/red]")
    for p in report.problems:
        console.print(p, style="yellow", markup=False, soft_wrap=True)  # one line, however long
    for bp in report.bad_parts:
        console.print(f"[yellow]unreadable part file {escape(str(bp.path))}: {escape(str(bp.error))}[/yellow]")
