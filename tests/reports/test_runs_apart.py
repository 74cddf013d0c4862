"""A unit is (run, unit id) everywhere (issue 36 item 2): runs read together that share unit ids -
the same sweep run three times - stay apart in every view, in the viewer's superseded marking, in
the paired tables and in the viewer's arm comparison; and a model has one name (item 5): the sweep's
label, in the calls view, @wasted_spend and the spend tables as in attempts and @failure_modes."""

from __future__ import annotations

import dataclasses
import http.client
from pathlib import Path

import pytest

from reports.build import ReportOptions, build_report
from reports.views import named_query, open_runs, run_query
from reports.webview.compare import compare
from reports.webview.search import SearchIndex
from reports.webview.server import serve, stop
from reports.webview.snapshot import build_snapshot
from schemas.parts import PartWriter
from tests.doubles.known_run import (
    REACT,
    RECAP,
    RUN_A_CALLS,
    RUN_A_EPISODES,
    RUN_A_EVENTS,
    RUN_A_MESSAGES,
    RUN_A_NODES,
    RUN_A_RUN,
    RUN_A_STEPS,
    SYNC,
    call,
    episode,
)

#: every view over the run's rows that keeps one row per episode, call, node or unit
PER_RUN_VIEWS = ("attempts", "terminal", "outcomes", "calls", "nodes", "tree_stats", "step_patterns", "episode_modes", "failures")


def write_copy(run_dir: Path, run_id: str, records: list) -> Path:
    """A run folder ``run_id`` holding ``records`` (the same unit ids as any other copy)."""
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "run.json").write_text(f'{{"run_id": "{run_id}", "spec_hash": "hashA"}}')
    PartWriter(run_dir, writer="sink0001").write_records(run_id, records)
    return run_dir


RUN_A_ALL = RUN_A_EPISODES + RUN_A_CALLS + RUN_A_STEPS + RUN_A_NODES + RUN_A_MESSAGES + RUN_A_EVENTS + RUN_A_RUN


@pytest.fixture(scope="module")
def three(tmp_path_factory) -> list[Path]:
    base = tmp_path_factory.mktemp("three")
    return [write_copy(base / f"r{i}", f"r{i}", RUN_A_ALL) for i in (1, 2, 3)]


def _per_run(con, view: str) -> dict[str, int]:
    return dict(run_query(con, f"SELECT run_id, count(*) FROM {view} GROUP BY 1").rows)


def test_three_runs_with_the_same_unit_ids_count_three_times(three):
    one = open_runs(three[:1])
    together = open_runs(three)
    for view in PER_RUN_VIEWS:
        (n,) = _per_run(one, view).values()
        assert n > 0, view
        assert _per_run(together, view) == {"r1": n, "r2": n, "r3": n}, view
    # the query: every run's 18 units, not one run's
    assert run_query(together, "SELECT run_id, count(*) FROM terminal GROUP BY 1 ORDER BY 1").rows == [
        ("r1", 18),
        ("r2", 18),
        ("r3", 18),
    ]
    # each run's superseded attempt (react t2/84 attempt 1) is superseded by its own run's attempt 2 only
    assert run_query(together, "SELECT run_id, episode_id FROM attempts WHERE NOT is_latest ORDER BY 1").rows == [
        ("r1", "A-react-t2-84-a1"),
        ("r2", "A-react-t2-84-a1"),
        ("r3", "A-react-t2-84-a1"),
    ]
    # the report's tables: three times the episodes and pairs, three times the spend
    by_split = {(r["model_label"], r["arm"], r["env_split"]): r["episodes"] for r in named_query(one, "success_by_split").dicts()}
    assert {
        (r["model_label"], r["arm"], r["env_split"]): r["episodes"] for r in named_query(together, "success_by_split").dicts()
    } == {k: 3 * v for k, v in by_split.items()}
    pairs = {
        (r["model_label"], r["env_split"], r["arm_a"], r["arm_b"]): r["pairs"] for r in named_query(one, "paired_methods").dicts()
    }
    assert pairs and {
        (r["model_label"], r["env_split"], r["arm_a"], r["arm_b"]): r["pairs"]
        for r in named_query(together, "paired_methods").dicts()
    } == {k: 3 * v for k, v in pairs.items()}
    wasted = {(r["model_label"], r["arm"]): (r["calls"], r["superseded_cost"]) for r in named_query(one, "wasted_spend").dicts()}
    assert {
        (r["model_label"], r["arm"]): (r["calls"], r["superseded_cost"]) for r in named_query(together, "wasted_spend").dicts()
    } == {k: (3 * c, 3 * s) for k, (c, s) in wasted.items()}
    for query, side in (
        ("paper_pairs", ("scope", "model_label", "arm_label", "ref_label", "benchmark", "split", "level", "task")),
        ("success_by_ablation", ("model_label", "method", "env_split", "window_size", "ablation")),
    ):
        one_pairs = {tuple(r[k] for k in side): r["pairs"] for r in named_query(one, query).dicts()}
        assert any(one_pairs.values()), query
        assert {tuple(r[k] for k in side): r["pairs"] for r in named_query(together, query).dicts()} == {
            k: None if v is None else 3 * v for k, v in one_pairs.items()
        }, query
    # @coverage and @runs: each run its own units
    assert [r["units"] for r in named_query(together, "runs").dicts()] == [18, 18, 18]


def _unit(eid: str, method: str, cfg: str, inst: str, end: str, *, attempt: int = 1, ended_at: float = 100.0):
    return episode(
        eid,
        method,
        cfg,
        "gpt-4o",
        SYNC,
        "t2",
        inst,
        42,
        end,
        cost=1.0,
        prompt=10,
        cached=0,
        completion=1,
        calls=1,
        steps=1,
        attempt=attempt,
        ended_at=ended_at,
    )


def test_viewer_marks_superseded_within_a_run(tmp_path):
    """Run 1 resolved the unit; run 2 (same unit id, later, attempt 2) failed it: neither run's row is
    superseded - run 2's failure is not a later attempt of run 1's unit."""
    r1 = write_copy(tmp_path / "r1", "r1", [_unit("e1", "recap", RECAP, "i2", "success")])
    r2 = write_copy(tmp_path / "r2", "r2", [_unit("e2", "recap", RECAP, "i2", "agent_done", attempt=2, ended_at=900.0)])
    server, thread = serve([r1, r2], 0, poll_s=0)
    try:
        pages = {path: _get(server, path) for path in ("/episodes", "/episode?run=r1&id=e1", "/episode?run=r2&id=e2")}
    finally:
        stop(server, thread)
    assert pages["/episodes"].count('<tr data-episode="') == 2 and "superseded" not in pages["/episodes"]
    assert "superseded" not in pages["/episode?run=r1&id=e1"] and "superseded" not in pages["/episode?run=r2&id=e2"]
    # a later attempt of the same unit in the same run does supersede it
    r3 = write_copy(
        tmp_path / "r3",
        "r3",
        [
            _unit("e1", "recap", RECAP, "i2", "success"),
            _unit("e3", "recap", RECAP, "i2", "agent_done", attempt=2, ended_at=900.0),
        ],
    )
    server, thread = serve([r3], 0, poll_s=0)
    try:
        assert _get(server, "/episodes").count("superseded") == 1
        assert "(superseded)" in _get(server, "/episode?run=r3&id=e1")
    finally:
        stop(server, thread)


def _get(server, path: str) -> str:
    conn = http.client.HTTPConnection("127.0.0.1", server.server_address[1], timeout=30)
    conn.request("GET", path)
    r = conn.getresponse()
    body = r.read().decode("utf-8")
    conn.close()
    assert r.status == 200, (path, body[:300])
    return body


def test_arm_compare_uses_every_run(tmp_path):
    """Four runs of recap and react on the same two units: 8 pairs (each run's recap and react
    paired), not 2; recap solved both in runs 1-3, react only in run 4."""
    runs = []
    for i in range(1, 5):
        rows = []
        for inst in ("i2", "i3"):
            rows.append(_unit(f"recap-{inst}", "recap", RECAP, inst, "success" if i < 4 else "agent_done", ended_at=100.0 * i))
            rows.append(
                _unit(f"react-{inst}", "react", REACT, inst, "agent_done" if i < 4 else "success", ended_at=100.0 * i + 1)
            )
        runs.append(write_copy(tmp_path / f"r{i}", f"r{i}", rows))
    snap = build_snapshot(runs, SearchIndex())
    try:
        c = compare(snap, "arm", "recap", "react")
        assert (c.pairs, c.a_successes, c.b_successes, c.a_only, c.b_only) == (8, 6, 2, 6, 2)
        # every pair within one run
        assert sorted((p["a_run"], p["b_run"]) for p in c.discordant) == sorted([(f"r{i}", f"r{i}") for i in range(1, 5)] * 2)
    finally:
        snap.close()
    con = open_runs(runs)
    (row,) = named_query(con, "paired_methods").dicts()
    assert (row["arm_a"], row["arm_b"], row["pairs"], row["a_successes"], row["b_successes"]) == ("react", "recap", 8, 2, 6)


def test_recap_sql_on_three_runs_counts_every_run(three):
    """The issue's command: ``recap sql A B C "select run_id, count(*) from terminal group by 1"``."""
    import contextlib
    import io
    import json

    from pipeline.cli.sql import sql_main

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        rc = sql_main([*map(str, three), "select run_id, count(*) AS n from terminal group by 1 order by 1", "--json"])
    assert (rc, json.loads(out.getvalue())) == (0, [{"run_id": f"r{i}", "n": 18} for i in (1, 2, 3)])


# -- item 5: one name for a model -----------------------------------------------------------------

NAMES = ("expert-noisy", "expert-calm")


def _named_model_run(run_dir: Path) -> Path:
    """Two sweep entries on one model string (``offline/expert``, a test double) named
    ``expert-noisy`` and ``expert-calm``: each ran recap on one unit, with one call each (the
    noisy one also a failed call) - as the pipeline writes them: episodes.model the name,
    llm_calls.model the model string, llm_calls.model_name the name."""
    rows: list = []
    for i, name in enumerate(NAMES):
        eid = f"{name}-e"
        ep = episode(
            eid,
            "recap",
            RECAP,
            "scripted",
            SYNC,
            "t2",
            "i2",
            42,
            "success" if i else "agent_done",
            cost=1.0 + i,
            prompt=10,
            cached=0,
            completion=1,
            calls=1,
            steps=1,
            test_double=True,
        )
        rows.append(dataclasses.replace(ep, unit_id=f"u-{name}", model=name, provider_model="offline/expert"))
        c = call(eid, 0, "task", (0, 1), model="offline/expert", prompt=10, completion=1, cost=0.5 + i, test_double=True)
        rows.append(dataclasses.replace(c, model_name=name))
        if not i:
            bad = call(eid, 1, "task", (0, 1), status="error", error_kind="server_error", cost=0.25, test_double=True)
            rows.append(dataclasses.replace(bad, model_name=name))
    return write_copy(run_dir, "named", rows)


def test_one_name_per_model_in_every_view(tmp_path):
    run = _named_model_run(tmp_path / "named")
    con = open_runs([run])
    want = {f"{n} (test double)" for n in NAMES}
    for view in ("attempts", "terminal", "calls", "episode_modes"):
        assert {r[0] for r in run_query(con, f"SELECT DISTINCT model_label FROM {view}").rows} == want, view
    # a failed call without a model string is still named by its sweep name
    assert run_query(con, "SELECT model_label, count(*) FROM calls GROUP BY 1 ORDER BY 1").rows == [
        ("expert-calm (test double)", 1),
        ("expert-noisy (test double)", 2),
    ]
    assert {(r["model_label"], r["calls"], r["cost_usd"]) for r in named_query(con, "wasted_spend").dicts()} == {
        ("expert-calm (test double)", 1, 1.5),
        ("expert-noisy (test double)", 2, 0.75),
    }
    assert [(r["model_label"], r["calls"], r["failed_calls"]) for r in named_query(con, "spend_by_model").dicts()] == [
        ("expert-calm (test double)", 1, 0),
        ("expert-noisy (test double)", 2, 1),
    ]
    for query in ("failure_modes", "costs", "success_by_model"):
        assert {r["model_label"] for r in named_query(con, query).dicts()} == want, query
    # the report's spend tables say the same names
    report = build_report([run], ReportOptions(formats=("md",)))
    spend = [t for s in report.sections for t in s.tables if t.source in ("spend_by_model", "wasted_spend")]
    assert len(spend) == 2
    for t in spend:
        assert {r["model_label"] for r in t.rows} == want, t.source
