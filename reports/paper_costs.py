"""The paper's cost tables filled from a run: ALFWorld's spend per game and Robotouille task 6's calls and dollars."""

from __future__ import annotations

from typing import Any

from reports import paper
from reports.model import Column, Table
from reports.paper_cells import Cells, Footnotes, arm_protocol, join_notes, method_rank, test_double_last
from reports.stat_notes import permutation_note
from reports.stats import SignFlipTest, clustered_permutation_test

#: a cell (or pair) of :class:`Cells`: column name to value
Cell = dict[str, Any]
#: a row of a table being filled: column name to value
Row = dict[str, Any]


def _cost_test(pr: Cell) -> SignFlipTest:
    """The permutation test of a pair row's cost differences, flipping whole instances."""
    return clustered_permutation_test(pr["cost_diffs"], pr["cost_instances"])


def _cost_p(cells: Cells, cell: Cell, pool: list[Cell], used: list[SignFlipTest]) -> float | None:
    """The cost p of ``cell`` against its reference; the test is appended to ``used`` (for the note)."""
    if cell["method"] == "recap" and cell["ablation"] == "original":
        return None
    pr = cells.pair(cell, cells.reference(cell, pool))
    if not pr:
        return None
    used.append(_cost_test(pr))
    return used[-1].p


def _by_model_then_method(c: Cell) -> tuple[bool, str, int, str]:
    """The cost tables' row order: real models before test doubles, then the paper's method order, then the arm."""
    return (*test_double_last(c["model_label"]), method_rank(paper.MAIN_ORDER, c["method"]), c["arm_label"])


def alfworld_cost_tables(cells: Cells) -> list[Table] | str:
    """The ALFWorld cost tables (totals per method, and the ReCAP/ReAct ratio on the games both ran); or the one
    line that says why they are left out."""
    pool = [c for c in cells.select(level="split", benchmark="alfworld") if c["ablation"] == "original"]
    if not pool:
        return "ALFWorld costs: no arm without an ablation ran ALFWorld."
    pool.sort(key=_by_model_then_method)
    out = [_alfworld_totals_table(cells, pool)]
    ratio = _alfworld_ratio_table(cells, pool)
    if ratio is not None:
        out.append(ratio)
    return out


def _alfworld_total_row(cells: Cells, c: Cell, pool: list[Cell], tests: list[SignFlipTest], notes: Footnotes) -> Row:
    """One arm's ALFWorld totals, beside the paper's total for its method where the protocols and game counts agree
    (a footnote says why not where they differ)."""
    ref = paper.COSTS["alfworld_134_games_usd"].get(c["method"])
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
    return row


def _alfworld_totals_table(cells: Cells, pool: list[Cell]) -> Table:
    """ALFWorld's total cost per arm over the games it ran, against the paper's 134-game totals."""
    notes = Footnotes()
    tests: list[SignFlipTest] = []
    rows = [_alfworld_total_row(cells, c, pool, tests, notes) for c in pool]
    return Table(
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
        join_notes(
            "p: the per-game cost difference against ReCAP of the same model, profile and window, on the games both ran.",
            permutation_note(tests, "p"),
            notes.text(),
        ),
    )


def _alfworld_ratio_row(cells: Cells, c: Cell, pool: list[Cell], tests: list[SignFlipTest], notes: Footnotes) -> Row | None:
    """A ReAct arm's cost set against its ReCAP reference on the games both ran; None for other methods, or
    where there is no reference or no paired cost."""
    if c["method"] != "react":
        return None
    ref_cell = cells.reference(c, pool)
    pr = cells.pair(c, ref_cell)
    if ref_cell is None or pr is None or not pr["arm_cost"]:
        return None
    totals = paper.COSTS["alfworld_134_games_usd"]
    paper_ratio = totals["recap"] / totals["react"]
    why = paper.mismatch(paper.PROTOCOLS["costs_alfworld"], arm_protocol(c)) or paper.mismatch(
        paper.PROTOCOLS["costs_alfworld"], arm_protocol(ref_cell)
    )
    test = _cost_test(pr)
    row = {
        "model": c["model_label"],
        "recap": ref_cell["arm_label"],
        "react": c["arm_label"],
        "games": pr["pairs"],
        "recap_cost": pr["ref_cost"],
        "react_cost": pr["arm_cost"],
        "ratio": pr["ref_cost"] / pr["arm_cost"],
        "p": test.p,
    }
    tests.append(test)
    if why is None:
        row["paper"], row["diff"] = f"{paper_ratio:.2f}", row["ratio"] - paper_ratio
    else:
        row["paper"] = notes.mark(why)
    return row


def _alfworld_ratio_table(cells: Cells, pool: list[Cell]) -> Table | None:
    """The ReCAP/ReAct cost ratio per model on the games both ran; None when no ReAct arm has a ReCAP pair."""
    notes = Footnotes()
    tests: list[SignFlipTest] = []
    rows = [row for c in pool if (row := _alfworld_ratio_row(cells, c, pool, tests, notes)) is not None]
    if not rows:
        return None
    return Table(
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
        rows,
        "paper_pairs",
        join_notes(
            "ratio = ReCAP's total / ReAct's total over the paired games; p: the per-game cost difference.",
            permutation_note(tests, "p"),
            notes.text(),
        ),
    )


def _task6_row(cells: Cells, c: Cell, pool: list[Cell], tests: list[SignFlipTest], notes: Footnotes) -> Row:
    """One arm's task-6 calls, tokens and dollars per episode; ReCAP's beside the paper's where the protocols agree
    (a footnote says why not where they differ)."""
    ref = paper.COSTS["robotouille_sync_task6"]
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
    return row


def task6_cost_table(cells: Cells) -> Table | str:
    """The task-6 cost table (calls, tokens and dollars per episode on synchronous task 6); or the one line that
    says why it is left out."""
    pool = [
        c
        for c in cells.select(level="task", benchmark="robotouille", split="synchronous")
        if paper.task_index(c["task"]) == 6 and c["ablation"] == "original"
    ]
    if not pool:
        return "Task-6 costs: no arm without an ablation ran Robotouille synchronous task 6."
    pool.sort(key=_by_model_then_method)
    notes = Footnotes()
    tests: list[SignFlipTest] = []
    rows = [_task6_row(cells, c, pool, tests, notes) for c in pool]
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
        join_notes(
            "The paper's task-6 cost is taken to come from its 20 task-6 runs (128-message window, as its tree analysis). "
            "p: the per-episode cost difference against ReCAP of the same model, profile and window.",
            permutation_note(tests, "p"),
            notes.text(),
        ),
    )
