"""The synthetic run generator (used by bench/reports.py) writes consistent, schema-true runs."""

from __future__ import annotations

import io

import pytest

from pipeline.cli.report import report_main
from reports.synthetic import SyntheticSpec, write_synthetic_run
from reports.views import named_query, open_runs, run_query


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    run = tmp_path_factory.mktemp("synth") / "run"
    counts = write_synthetic_run(
        run, SyntheticSpec(messages=6000, mean_calls=30, window=16, seed=3, part_rows=2000, row_group_rows=500)
    )
    return run, counts


def test_rows_agree_with_each_other(synthetic):
    run, counts = synthetic
    con = open_runs([run])
    assert run_query(con, "SELECT count(*) FROM messages").rows == [(counts["messages"],)]
    assert 5000 <= counts["messages"] <= 7000  # about the asked 6000 (Poisson call counts)
    assert len(list((run / "messages").glob("part-*.parquet"))) == -(-counts["messages"] // 2000)
    # an episode row's call count and token totals are its calls' (successful calls carry tokens)
    assert run_query(
        con,
        """
        SELECT count(*) FROM episodes e JOIN (
          SELECT episode_id, count(*) AS n, sum(prompt_tokens) AS p, sum(cost_usd) AS c FROM llm_calls GROUP BY ALL
        ) c USING (episode_id)
        WHERE e.llm_calls <> c.n OR e.prompt_tokens <> c.p OR abs(e.cost_usd - c.c) > 1e-9""",
    ).rows == [(0,)]
    # messages: 2 pinned + a prompt and a reply per call; windows never exceed 16 and keep both pins
    assert run_query(
        con,
        """
        SELECT count(*) FROM episodes e JOIN (SELECT episode_id, count(*) AS m FROM messages GROUP BY ALL) m USING (episode_id)
        WHERE m.m <> 2 * e.llm_calls + 2""",
    ).rows == [(0,)]
    assert run_query(
        con, "SELECT max(len(window_seqs)), bool_and(window_seqs[1] = 0 AND window_seqs[2] = 1) FROM llm_calls"
    ).rows == [(16, True)]
    assert run_query(
        con,
        "SELECT count(*) FROM llm_calls c JOIN messages m ON m.episode_id = c.episode_id AND m.seq = c.response_seq WHERE m.role <> 'assistant'",
    ).rows == [(0,)]
    # every tree hangs from one root
    assert run_query(
        con, "SELECT count(*) FROM (SELECT episode_id FROM tree_nodes WHERE parent_id IS NULL GROUP BY ALL HAVING count(*) <> 1)"
    ).rows == [(0,)]
    assert run_query(
        con,
        "SELECT count(*) FROM tree_nodes n LEFT JOIN tree_nodes p ON p.episode_id = n.episode_id AND p.node_id = n.parent_id WHERE n.parent_id IS NOT NULL AND (p.node_id IS NULL OR p.depth <> n.depth - 1)",
    ).rows == [(0,)]


def test_report_over_synthetic_run(synthetic, tmp_path):
    run, counts = synthetic
    out, err = io.StringIO(), io.StringIO()
    assert report_main([str(run), "--out", str(tmp_path)], stdout=out, stderr=err) == 0, err.getvalue()
    con = open_runs([run])
    summary = {r["arm"]: r for r in named_query(con, "context_summary").dicts()}
    assert set(summary) == {"act", "react", "recap"}
    assert {a: r["max_window_messages"] for a, r in summary.items()} == {"act": 16, "react": 16, "recap": 16}
    modes = dict(run_query(con, "SELECT mode, count(*) FROM episode_modes GROUP BY ALL").rows)
    assert sum(modes.values()) == run_query(con, "SELECT count(*) FROM episodes").rows[0][0]
    assert modes.get("repeated_action_loop", 0) > 0  # the generator's a-b loops are found
