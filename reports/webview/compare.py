"""The compare page's SQL and tests: two runs or two arms paired unit by unit, with McNemar and permutation p."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

from reports.stats import SignFlipTest, clustered_mcnemar_exact, clustered_permutation_test, instance_discordance
from reports.webview.errors import BadRequest
from reports.webview.snapshot import Snapshot


@dataclass
class Comparison:
    """Two runs or two arms (``kind``) compared on the units both ran: successes, discordant pairs with the
    clustered McNemar p, cost difference (a minus b) with a permutation p, overall and per task. Both tests swap
    the two sides within an instance, all its seeds together (:mod:`reports.stats`); with one seed per instance
    they are the exact McNemar test and the ordinary paired sign-flip test. ``instances`` counts the paired
    instances (group, split, task, instance); ``cost_test`` says how the cost p was computed."""

    kind: str  # "run" or "arm"
    a: str
    b: str
    per_task: list[dict[str, Any]]
    pairs: int
    a_successes: int
    b_successes: int
    a_only: int
    b_only: int
    p_value: float
    mean_cost_diff: float | None
    cost_p: float | None
    discordant: list[dict[str, Any]]
    elapsed_ms: float
    instances: int = 0
    cost_test: SignFlipTest | None = None


def _side_sql(kind: str, columns: set[str]) -> str:
    """Per-unit outcomes of one side, one row per unit - a unit is (run, unit id), so runs read
    together that share unit ids each count their own units. Two runs: each run's counted row of
    each unit (its latest finished attempt, else its latest: ``is_unit_row``), grouped by arm and
    model. Two arms: the rows the report's paired table counts (terminal, finished) of every run,
    grouped by model, like reports/sql/paired_methods.sql."""
    cols = (
        "SELECT {side} AS side, {grp} AS grp, env_split, task, instance_id, sampling_seed, run_id, episode_id, success, "
        "cost_usd, end_reason, mode, ended_at FROM _episode_list "
    )
    finished_first = "finished DESC, " if "finished" in columns else ""
    if kind == "run":
        return (
            cols.format(side="run_id", grp="arm || ' · ' || model_label")
            + f"QUALIFY row_number() OVER (PARTITION BY run_id, unit_id ORDER BY {finished_first}attempt DESC, "
            "ended_at DESC, episode_id DESC) = 1"
        )
    counted = "is_unit_row" if "is_unit_row" in columns else "is_latest"
    return cols.format(side="arm", grp="model_label") + f"WHERE {counted}" + (" AND finished" if "finished" in columns else "")


#: the pair's key: a unit of one group (arm and model, or model) on one instance and seed
_KEY = ("grp", "env_split", "task", "instance_id", "sampling_seed")
_SAME_KEY = " AND ".join(f"o.{k} = u.{k}" for k in _KEY)

#: one row per pair: the two sides' units of one key. A key both sides ran in one run pairs within
#: that run (shared, run by run: four runs of both arms give four pairs); a side's other units of
#: the key pair with the other side's leftovers, latest with latest (rep), as two single runs pair.
_PAIRS_SQL = (
    """
    WITH s AS ({sides}), x0 AS (SELECT * FROM s WHERE side = $a), y0 AS (SELECT * FROM s WHERE side = $b),
    x AS (SELECT u.*, EXISTS (SELECT 1 FROM y0 o WHERE o.run_id = u.run_id AND """
    + _SAME_KEY
    + """) AS shared FROM x0 u),
    y AS (SELECT u.*, EXISTS (SELECT 1 FROM x0 o WHERE o.run_id = u.run_id AND """
    + _SAME_KEY
    + """) AS shared FROM y0 u),
    xr AS (SELECT *, row_number() OVER (PARTITION BY {key} ORDER BY {rank}) AS rep FROM x),
    yr AS (SELECT *, row_number() OVER (PARTITION BY {key} ORDER BY {rank}) AS rep FROM y)
    SELECT x.grp, x.env_split, x.task, x.instance_id, x.sampling_seed,
      x.run_id AS a_run, x.episode_id AS a_episode, x.success AS a_success, x.cost_usd AS a_cost, coalesce(x.mode, x.end_reason) AS a_mode,
      y.run_id AS b_run, y.episode_id AS b_episode, y.success AS b_success, y.cost_usd AS b_cost, coalesce(y.mode, y.end_reason) AS b_mode
    FROM xr x JOIN yr y ON x.grp = y.grp AND x.env_split = y.env_split AND x.task = y.task AND x.instance_id = y.instance_id
      AND x.sampling_seed = y.sampling_seed AND x.rep = y.rep
    ORDER BY x.grp, x.env_split, x.task, x.instance_id, x.sampling_seed, x.rep"""
)
_RANK = "shared DESC, CASE WHEN shared THEN run_id END DESC, ended_at DESC, run_id DESC, episode_id DESC"


def _check_sides(snap: Snapshot, kind: str, a: str, b: str) -> None:
    """A 400 for an unknown kind, an unknown side or the same side twice."""
    if kind not in ("run", "arm"):
        raise BadRequest("compare what? kind must be run or arm")
    col = "run_id" if kind == "run" else "arm"
    known = {str(v) for v in snap.query(f"SELECT DISTINCT {col} FROM _episode_list").column(col)}
    for side in (a, b):
        if side not in known:
            raise BadRequest(f"no {kind} named {side!r}" if side else f"choose two {kind}s to compare")
    if a == b:
        raise BadRequest(f"choose two different {kind}s")


def _cost_diff(p: dict[str, Any]) -> float:
    return (p["a_cost"] or 0.0) - (p["b_cost"] or 0.0)


def _per_task(pairs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The comparison per (group, split, task), in the order the pairs come: counts, the clustered McNemar p
    over the task's instances and the mean cost difference."""
    per: dict[tuple[str, str, str], dict[str, Any]] = {}
    for p in pairs:
        t = per.setdefault(
            (p["grp"], p["env_split"], p["task"]),
            {
                "group": p["grp"],
                "env_split": p["env_split"],
                "task": p["task"],
                "pairs": 0,
                "a_successes": 0,
                "b_successes": 0,
                "a_only": 0,
                "b_only": 0,
                "cost_diffs": [],
                "a_ok": [],
                "b_ok": [],
                "instances": [],
            },
        )
        t["pairs"] += 1
        t["a_successes"] += bool(p["a_success"])
        t["b_successes"] += bool(p["b_success"])
        t["a_only"] += bool(p["a_success"] and not p["b_success"])
        t["b_only"] += bool(p["b_success"] and not p["a_success"])
        t["cost_diffs"].append(_cost_diff(p))
        t["a_ok"].append(bool(p["a_success"]))
        t["b_ok"].append(bool(p["b_success"]))
        t["instances"].append(p["instance_id"])
    per_task = []
    for t in per.values():
        diffs = t.pop("cost_diffs")
        keys = t.pop("instances")
        t["p_value"] = float(clustered_mcnemar_exact(instance_discordance(t.pop("a_ok"), t.pop("b_ok"), keys)))
        t["instances"] = len(set(keys))
        t["mean_cost_diff"] = sum(diffs) / len(diffs)
        per_task.append(t)
    return per_task


def compare(snap: Snapshot, kind: str, a: str, b: str) -> Comparison:
    """Compare ``a`` with ``b`` (two run ids or two arm labels) on paired units (see :func:`_side_sql`); a 400
    for an unknown kind, an unknown side or the same side twice."""
    t0 = time.perf_counter()
    _check_sides(snap, kind, a, b)
    sql = _PAIRS_SQL.format(sides=_side_sql(kind, snap.columns), key=", ".join(_KEY), rank=_RANK)
    pairs = snap.query(sql, {"a": a, "b": b}).dicts()
    # the unit of the tests: one instance of one group (arm and model, or model) and split
    inst = [(p["grp"], p["env_split"], p["task"], p["instance_id"]) for p in pairs]
    per_task = _per_task(pairs)
    diffs = [_cost_diff(p) for p in pairs]
    a_only = sum(1 for p in pairs if p["a_success"] and not p["b_success"])
    b_only = sum(1 for p in pairs if p["b_success"] and not p["a_success"])
    discordance = instance_discordance([bool(p["a_success"]) for p in pairs], [bool(p["b_success"]) for p in pairs], inst)
    cost_test = clustered_permutation_test(diffs, inst) if diffs else None
    return Comparison(
        kind,
        a,
        b,
        per_task,
        len(pairs),
        sum(bool(p["a_success"]) for p in pairs),
        sum(bool(p["b_success"]) for p in pairs),
        a_only,
        b_only,
        float(clustered_mcnemar_exact(discordance)),
        sum(diffs) / len(diffs) if diffs else None,
        cost_test.p if cost_test else None,
        [p for p in pairs if bool(p["a_success"]) != bool(p["b_success"])],
        (time.perf_counter() - t0) * 1000,
        len(set(inst)),
        cost_test,
    )


def compare_choices(snap: Snapshot) -> dict[str, list[str]]:
    """The run ids and arm labels a comparison can choose from, sorted."""
    return {
        "run": [str(v) for v in snap.query("SELECT DISTINCT run_id FROM _episode_list ORDER BY 1").column("run_id")],
        "arm": [str(v) for v in snap.query("SELECT DISTINCT arm FROM _episode_list ORDER BY 1").column("arm")],
    }
