"""The task-tree section: depth, branching and leaf failures of the trees beside the paper's figures."""

from __future__ import annotations

from reports import paper, svg
from reports.model import Column, Plot, Section, Table
from reports.sections.common import Query, series_label, unique


def trees(q: Query) -> Section:
    """The task-tree section: depth, branching and leaf failures of the trees, beside the paper's figures, with
    their distributions plotted."""
    t = paper.TREE
    sec = Section(
        "trees",
        "Task trees",
        "From tree_nodes of the latest attempts. depth = deepest node in edges from the root (root 0); "
        "levels = depth + 1 (root = level 1, as in the level_N ablations); branching factor = mean "
        "number of children over the nodes that have children (all subtasks a node pushed, over all "
        "its refinements), averaged over episodes; leaf failures = failed leaf nodes. The paper does not "
        f"define its measures; it reports depth {t['depth']} and branching factor {t['branching_factor']} "
        f"on average over {t['episodes']} runs of {t['task']}.",
    )
    rows = q("tree_summary").dicts()
    sec.tables.append(
        Table(
            "trees",
            "Tree depth, branching factor and leaf failures",
            [
                Column("model_label", "model"),
                Column("arm", "method"),
                Column("env_split", "split"),
                Column("episodes", "episodes", "int"),
                Column("mean_levels", "levels", "float"),
                Column("mean_max_depth", "depth", "float"),
                Column("max_depth_sd", "sd", "float"),
                Column("mean_branching_factor", "branching", "float"),
                Column("branching_factor_sd", "sd", "float"),
                Column("max_children", "max children", "int"),
                Column("nodes_per_episode", "nodes/episode", "float"),
                Column("leaf_failures_per_episode", "leaf failures/episode", "float"),
                Column("leaf_failures", "leaf failures", "int"),
                Column("refinements_per_episode", "refinements/episode", "float"),
            ],
            rows,
            "tree_summary",
        )
    )
    dist = q("tree_distribution").dicts()
    models = unique(r["model_label"] for r in dist)
    titles = {
        "levels": "Tree levels per episode",
        "branching_factor": "Branching factor per episode (bin [k, k+1))",
        "leaf_failures": "Leaf failures per episode",
    }
    for metric, title in titles.items():
        rs = [r for r in dist if r["metric"] == metric]
        if not rs:
            continue
        cats = [str(v) for v in sorted(unique(r["value"] for r in rs))]
        series = unique(series_label(r["model_label"], r["arm"], models) for r in rs)
        values = {(str(r["value"]), series_label(r["model_label"], r["arm"], models)): float(r["episodes"]) for r in rs}
        sec.plots.append(
            Plot(f"tree_{metric}", title, svg.grouped_bars(title, cats, series, values, y_label="episodes"), "tree_distribution")
        )
    return sec
