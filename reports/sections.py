"""The report's sections: each runs its SQL files and lays the results out as tables and plots.

Numbers come only from the SQL in ``reports/sql/`` (the cost permutation test is computed from
the per-pair differences and their instances that ``paired_methods.sql`` returns). Each table's
note names its intervals and tests from the rows shown (:mod:`reports.stat_notes`). Pivoting a long SQL result into
the paper's layout (methods x splits) happens here; the long results themselves go to CSV.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import duckdb

from reports import paper, svg
from reports.model import Column, Plot, Section, Table
from reports.stat_notes import interval_note, mcnemar_note, permutation_note, rate_clustered
from reports.stats import clustered_permutation_test, comparisons, holm
from reports.views import Result, named_query

Query = Callable[[str], Result]


def make_query(con: duckdb.DuckDBPyConnection, results: dict[str, Result]) -> Query:
    """Run each named SQL file once; keep every result for the CSV output. The run folders'
    plans are loaded first (:func:`load_plans`), for the coverage table."""
    load_plans(con)

    def q(name: str) -> Result:
        if name not in results:
            results[name] = named_query(con, name)
        return results[name]

    return q


#: the plan a run folder keeps (pipeline.store.PLAN_FILE) and its sweep file (SPEC_FILE)
PLAN_FILE = "plan.json"
SPEC_FILE = "spec.yaml"
#: the model-string prefix of the pipeline's test-double models (pipeline.spec.OFFLINE_PREFIX)
_TEST_DOUBLE_PREFIX = "offline/"


def _test_double_models(run_dir: Path) -> dict[str, bool]:
    """Model label -> test double, from the run folder's sweep file ({} when it cannot be read)."""
    import yaml

    try:
        data = yaml.safe_load((run_dir / SPEC_FILE).read_text(encoding="utf-8"))
        out = {}
        for m in data.get("models") or []:
            model = str(m["model"])
            out[str(m.get("label") or model)] = model.startswith(_TEST_DOUBLE_PREFIX)
        return out
    except Exception:  # noqa: BLE001 - no sweep file, or not one: the episode rows tell instead
        return {}


def load_plans(con: duckdb.DuckDBPyConnection) -> dict[str, str]:
    """Fill ``planned_units`` (reports/sql/views.sql) from each run folder's plan.json, read
    here in Python (the connection itself reaches no file). Returns run folder -> how its plan
    was read (``plan.json``, ``no plan.json``, ``unreadable plan.json: ...``). Done once per
    connection; a folder without a readable plan is left to the coverage query's fallback."""
    import json

    import pyarrow as pa

    if (con.execute("SELECT count(*) FROM planned_units").fetchone() or (0,))[0]:
        return {}
    cols: dict[str, list[Any]] = {
        k: [] for k in ("run_dir", "run_id", "unit_id", "label", "method", "model", "instance_id", "seed", "test_double")
    }
    how: dict[str, str] = {}
    for run_dir, run_id in con.execute("SELECT run_dir, run_json_id FROM run_dirs ORDER BY run_dir").fetchall():
        path = Path(run_dir) / PLAN_FILE
        try:
            units = json.loads(path.read_text(encoding="utf-8"))["units"]
            # plan.json's "method" is the arm's label; "method_name" the method (schema version 2)
            rows = [
                (
                    str(u["unit_id"]),
                    str(u["method"]),
                    u.get("method_name"),
                    str(u["model"]),
                    str(u.get("instance_id") or ""),
                    u.get("seed"),
                )
                for u in units
            ]
        except FileNotFoundError:
            how[run_dir] = f"no {PLAN_FILE}"
            continue
        except (OSError, ValueError, KeyError, TypeError) as exc:
            how[run_dir] = f"unreadable {PLAN_FILE}: {type(exc).__name__}"
            continue
        doubles = _test_double_models(Path(run_dir))
        how[run_dir] = PLAN_FILE
        for uid, label, method, model, inst, seed in rows:
            for k, v in zip(
                cols,
                (
                    run_dir,
                    run_id,
                    uid,
                    label,
                    method if isinstance(method, str) else None,
                    model,
                    inst,
                    seed if isinstance(seed, int) and not isinstance(seed, bool) else None,
                    doubles.get(model),
                ),
            ):
                cols[k].append(v)
    if cols["unit_id"]:
        types = {"seed": pa.int64(), "test_double": pa.bool_()}
        table = pa.table({k: pa.array(v, type=types.get(k, pa.string())) for k, v in cols.items()})  # noqa: F841
        con.register("_planned_units", table)
        try:
            con.execute("INSERT INTO planned_units SELECT * FROM _planned_units")
        finally:
            con.unregister("_planned_units")
    return how


def _unique(values: Iterable[Any]) -> list[Any]:
    seen: dict[Any, None] = {}
    for v in values:
        seen.setdefault(v, None)
    return list(seen)


def _rate_ci(row: dict[str, Any]) -> tuple[int, int, float, float]:
    return (row["successes"], row["episodes"], row["ci_low"], row["ci_high"])


def _is_test_double(model_label: str) -> bool:
    return model_label.endswith(" (test double)")


def _row_order(key: tuple[str, str]) -> tuple[bool, str, str]:
    """Pivot rows: real models first, then test doubles; by model, then method."""
    return (_is_test_double(key[0]), key[0], key[1])


def _series_label(model: str, arm: str, models: list[str]) -> str:
    return arm if len(models) <= 1 else f"{arm} · {model}"


# -- overview -----------------------------------------------------------------------------------


def overview(q: Query) -> Section:
    """The overview section: what the report covers, the runs, each arm's coverage (done, capped, gave up, not
    started), skipped part files and the events summary."""
    sec = Section("overview", "Overview")
    ov = q("overview").dicts()[0]
    labels = {
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
    rows = [{"metric": labels[k], "value": f"${v:,.4f}" if k == "spend_usd" else f"{v:,}"} for k, v in ov.items()]
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
        sec.tables.append(
            Table(
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
        )
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


#: Where the paper's numbers are: only the paper section puts them beside an arm, and only after
#: checking that the arm ran the paper's protocol (model, profile, window, step caps, tasks).
PAPER_POINTER = "The paper's values stand in the Paper section, beside arms that ran the paper's protocol."


# -- success rates -------------------------------------------------------------------------------


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
    splits = _unique(r["env_split"] for r in main)
    keys = sorted(_unique((r["model_label"], r["arm"]) for r in main), key=_row_order)
    cols = [Column("model", "model"), Column("arm", "method")] + [Column(s, s, "rate_ci") for s in splits]
    rows = []
    for m, a in keys:
        row: dict[str, Any] = {"model": m, "arm": a}
        for r in main:
            if (r["model_label"], r["arm"]) == (m, a):
                row[r["env_split"]] = _rate_ci(r)
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

    models = _unique(r["model_label"] for r in main)
    arms = _unique(_series_label(r["model_label"], r["arm"], models) for r in main)
    values = {(r["env_split"], _series_label(r["model_label"], r["arm"], models)): 100 * r["success_rate"] for r in main}
    errors = {
        (r["env_split"], _series_label(r["model_label"], r["arm"], models)): (100 * r["ci_low"], 100 * r["ci_high"]) for r in main
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

    per_task = q("success_by_task").dicts()
    for s in _unique(r["env_split"] for r in per_task):
        rs = [r for r in per_task if r["env_split"] == s]
        split_models = _unique(r["model_label"] for r in rs)
        series = _unique(_series_label(r["model_label"], r["arm"], split_models) for r in rs)
        rows = []
        for task in _unique(r["task"] for r in rs):
            row = {"task": task}
            for r in rs:
                if r["task"] == task:
                    row[_series_label(r["model_label"], r["arm"], split_models)] = _rate_ci(r)
            rows.append(row)
        note = ("model: " + ", ".join(split_models) + ". " if len(split_models) == 1 else "") + interval_note(rs)
        sec.tables.append(
            Table(
                f"tasks_{_slug(s)}",
                f"Success rate per task: {s}",
                [Column("task", "task")] + [Column(x, x, "rate_ci") for x in series],
                rows,
                "success_by_task",
                note,
            )
        )

    by_model = q("success_by_model").dicts()
    arms_m = _unique(r["arm"] for r in by_model)
    cols = [Column("model", "model")] + [Column(a, a, "rate_ci") for a in arms_m]
    rows = []
    for m in sorted(_unique(r["model_label"] for r in by_model), key=lambda x: (_is_test_double(x), x)):
        row = {"model": m}
        for r in by_model:
            if r["model_label"] == m:
                row[r["arm"]] = _rate_ci(r)
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

    abl = q("success_by_ablation").dicts()
    if any(r["ablation"] != "original" for r in abl):
        for r, adj in zip(abl, holm([r["p_value"] for r in abl])):
            r["p_holm"] = adj
            r["rate_ci"] = _rate_ci(r)
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
                + _comparisons_note(comparisons([r["p_value"] for r in abl]), "McNemar test"),
            )
        )

    paired = q("paired_methods").dicts()
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
            + _comparisons_note(comparisons([r["p_value"] for r in paired]), "McNemar test")
            + " "
            + _comparisons_note(comparisons([r["cost_p"] for r in paired]), "cost test", "Holm cost p"),
        )
    )
    return sec


def _comparisons_note(m: int, what: str, column: str = "Holm p") -> str:
    """How many tests a table's p column holds, and that its Holm column adjusts over them."""
    noun = what if m == 1 else what + "s"
    return f"{m} {noun} in this table; {column}: Holm-adjusted over {'it' if m == 1 else f'those {m}'} (family-wise error)."


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in text).strip("_")


# -- costs -----------------------------------------------------------------------------------------


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
    splits = _unique(r["env_split"] for r in rows)
    models = _unique(r["model_label"] for r in rows)
    series = _unique(_series_label(r["model_label"], r["arm"], models) for r in rows)
    values = {(r["env_split"], _series_label(r["model_label"], r["arm"], models)): r["cost_per_episode"] for r in rows}
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
    return sec


# -- context bound ---------------------------------------------------------------------------------


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
    models = _unique(r["model_label"] for r in per_call)
    series: dict[str, list[tuple[float, float]]] = {}
    for r in per_call:
        series.setdefault(_series_label(r["model_label"], r["arm"], models), []).append(
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


# -- task trees -----------------------------------------------------------------------------------


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
    models = _unique(r["model_label"] for r in dist)
    titles = {
        "levels": "Tree levels per episode",
        "branching_factor": "Branching factor per episode (bin [k, k+1))",
        "leaf_failures": "Leaf failures per episode",
    }
    for metric, title in titles.items():
        rs = [r for r in dist if r["metric"] == metric]
        if not rs:
            continue
        cats = [str(v) for v in sorted(_unique(r["value"] for r in rs))]
        series = _unique(_series_label(r["model_label"], r["arm"], models) for r in rs)
        values = {(str(r["value"]), _series_label(r["model_label"], r["arm"], models)): float(r["episodes"]) for r in rs}
        sec.plots.append(
            Plot(f"tree_{metric}", title, svg.grouped_bars(title, cats, series, values, y_label="episodes"), "tree_distribution")
        )
    return sec


# -- failure modes ---------------------------------------------------------------------------------

MODE_NOTE = (
    "One mode per episode, first match wins: success; model_error:<kind> (LLM error, kind of the "
    "last failed call); json_failures, truncated (a reply cut at the output cap), budget_exhausted, "
    "episode_limit, env_error; then for step "
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
    modes = sorted(_unique(r["mode"] for r in by_arm), key=lambda m: (m != "success", m))
    keys = sorted(_unique((r["model_label"], r["arm"]) for r in by_arm), key=_row_order)
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
    models = _unique(m for m, _ in keys)
    cats = [_series_label(m, a, models) for m, a in keys]
    counts = {(_series_label(r["model_label"], r["arm"], models), r["mode"]): float(r["episodes"]) for r in by_arm}
    sec.plots.append(
        Plot(
            "failure_modes",
            "Failure modes by method",
            svg.stacked_shares("Failure modes by method", cats, modes, counts),
            "failure_modes_by_arm",
        )
    )
    return sec
