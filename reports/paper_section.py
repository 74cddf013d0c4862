"""The ``paper`` section: the ReCAP paper's tables, laid out as in the paper, filled from a run.

Every number comes from ``reports/sql/paper_cells.sql``, ``paper_pairs.sql`` and
``paper_trees.sql``; this module only picks cells, pivots them into the paper's layout and adds
the paper's numbers (:mod:`reports.paper`). A success cell is four columns: ours as
``rate [95% CI] k/n`` (Wilson's interval widened for repeated seeds of one instance: the SQL
macros ``cluster_wilson_low/high``), the paper's value, the difference in points, and a McNemar
p-value against ReCAP on the units both arms ran (ablations: against the original), clustered by
instance (``clustered_mcnemar_p``: the exact McNemar test when each instance ran one seed), with
Holm's adjustment over the table beside it. Cost p-values flip the signs of whole instances
(:func:`reports.stats.clustered_permutation_test`). Each table's note names its interval and
tests from the cells it shows (:mod:`reports.stat_notes`).

A paper number stands only beside an arm that ran the paper's protocol for that table (model,
profile, window, step multipliers, tasks: :func:`reports.paper.mismatch`); elsewhere the paper
cell holds a footnote mark ``[n]`` and the table's note says why. A table whose protocol the run
did not follow at all is left out; the ``paper_omitted`` table says, in one line each, what is
missing. Each laid-out table is also added to the report's results (``paper_table_<name>``), so
the CSV output holds the tables exactly as shown.
"""

from __future__ import annotations

from reports import paper
from reports.model import Column, Section, Table, format_value
from reports.paper_cells import INTRO, Cells, Footnotes, Query, arm_protocol, join_notes, test_double_last
from reports.paper_costs import alfworld_cost_tables, task6_cost_table
from reports.paper_fever import fever_label_tables
from reports.paper_rates import ablation_table, cross_model_table, main_table, per_task_tables
from reports.views import Result


def tree_table(q: Query) -> Table | str:
    """The task-tree statistics (depth and branching of ReCAP's trees on synchronous task 6) beside the paper's;
    or the one line that says why it is left out."""
    trees = [t for t in q("paper_trees").dicts() if t["method"] == "recap" and t["ablation"] == "original"]
    if not trees:
        return "Tree statistics: no ReCAP arm without an ablation has task trees on Robotouille synchronous task 6."
    trees.sort(key=lambda t: (*test_double_last(t["model_label"]), t["arm_label"]))
    notes = Footnotes()
    rows = []
    for t in trees:
        row = {
            "model": t["model_label"],
            "method": t["arm_label"],
            "window": ", ".join(str(w) for w in t["windows"]),
            "episodes": t["episodes"],
            "levels": t["mean_levels"],
            "levels_sd": t["levels_sd"],
            "branching": t["mean_branching"],
            "branching_sd": t["branching_sd"],
        }
        why = paper.mismatch(paper.PROTOCOLS["trees"], arm_protocol(t))
        if why is None:
            row["paper_depth"], row["diff_depth"] = f"{paper.TREE['depth']:.1f}", t["mean_levels"] - paper.TREE["depth"]
            row["paper_branching"] = f"{paper.TREE['branching_factor']:.1f}"
            row["diff_branching"] = None if t["mean_branching"] is None else t["mean_branching"] - paper.TREE["branching_factor"]
        else:
            row["paper_depth"] = row["paper_branching"] = notes.mark(why)
        rows.append(row)
    return Table(
        "paper_trees",
        "Task trees on Robotouille synchronous task 6: depth and branching factor (paper §Task Tree Analysis)",
        [
            Column("model", "model"),
            Column("method", "method"),
            Column("window", "window"),
            Column("episodes", "episodes", "int"),
            Column("levels", "depth (levels)", "float"),
            Column("levels_sd", "sd", "float"),
            Column("branching", "branching", "float"),
            Column("branching_sd", "sd", "float"),
            Column("paper_depth", "paper depth", "text"),
            Column("diff_depth", "diff depth", "float"),
            Column("paper_branching", "paper branching", "text"),
            Column("diff_branching", "diff branching", "float"),
        ],
        rows,
        "paper_trees",
        join_notes(
            "depth = levels of the tree, the root being level 1 (the level_N ablations' convention); branching = mean "
            "children per node that has children; both per episode, then averaged. The paper defines neither and "
            "reports no test here.",
            notes.text(),
        ),
    )


def paper_section(q: Query, results: dict[str, Result] | None = None) -> Section:
    """The section; with ``results``, each laid-out table is added as ``paper_table_<name>``."""
    cells = Cells(q)
    sec = Section("paper", "The paper's tables", INTRO)
    omitted: list[dict[str, str]] = []
    built: list[Table | list[Table] | str] = [
        main_table(cells),
        per_task_tables(cells, "synchronous"),
        per_task_tables(cells, "asynchronous"),
        fever_label_tables(cells),
        cross_model_table(cells),
        ablation_table(cells),
        alfworld_cost_tables(cells),
        task6_cost_table(cells),
        tree_table(q),
    ]
    for item in built:
        if isinstance(item, str):
            table, _, missing = item.partition(": ")
            omitted.append({"table": table, "missing": missing})
        elif isinstance(item, list):
            sec.tables.extend(item)
        else:
            sec.tables.append(item)
    if omitted:
        sec.tables.append(
            Table(
                "paper_omitted",
                "Paper tables left out: what the run did not run",
                [Column("table", "table"), Column("missing", "what is missing")],
                omitted,
                "paper_cells",
            )
        )
    if results is not None:
        for t in sec.tables:
            results[f"paper_table_{t.name.removeprefix('paper_')}"] = Result(
                [c.key for c in t.columns], [tuple(format_value(c.kind, r.get(c.key)) for c in t.columns) for r in t.rows]
            )
    return sec
