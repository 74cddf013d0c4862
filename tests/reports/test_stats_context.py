"""reports/sql/context_summary.sql: prompt growth per episode after the window fills, summarised
over episodes (median and interquartile range), on hand-made ``calls`` and ``attempts`` rows."""

from __future__ import annotations

import duckdb
import numpy as np
import pytest

from reports.views import load_sql
from tests.reports.conftest import assert_rows

# (episode, window size K, [(call_index, window_len, prompt_tokens)], latest attempt)
EPISODES = [
    # fills at call 2 (largest window 6 >= K = 4): tokens 300, 310, 330, 340 at x = 2..5 -> 70 / 5
    ("e1", 4, [(0, 2, 100), (1, 4, 200), (2, 6, 300), (3, 6, 310), (4, 6, 330), (5, 6, 340)], True),
    # fills at call 1 and stays flat -> 0
    ("e2", 4, [(0, 2, 100), (1, 4, 150), (2, 4, 150), (3, 4, 150)], True),
    # block drops after the fill: 300, 250, 350 at x = 2..4 -> 50 / 2
    ("e3", 4, [(0, 2, 100), (1, 4, 200), (2, 6, 300), (3, 4, 250), (4, 6, 350)], True),
    # never reaches K = 8: no slope (its growth before the fill is what pooling would add)
    ("e4", 8, [(0, 2, 100), (1, 4, 400), (2, 6, 900)], True),
    # fills at its last call: one call after the fill is no slope
    ("e5", 4, [(0, 2, 100), (1, 6, 500)], True),
    # a superseded attempt: left out
    ("e6", 4, [(0, 6, 100), (1, 6, 9000)], False),
]


@pytest.fixture(scope="module")
def con():
    c = duckdb.connect(":memory:")
    c.execute("CREATE TABLE attempts (run_id VARCHAR, episode_id VARCHAR, window_size BIGINT)")
    c.execute(
        "CREATE TABLE calls (run_id VARCHAR, episode_id VARCHAR, model_label VARCHAR, arm VARCHAR, call_index BIGINT, "
        "status VARCHAR, latest_attempt BOOLEAN, prompt_tokens BIGINT, window_len BIGINT)"
    )
    for eid, k, calls, latest in EPISODES:
        c.execute("INSERT INTO attempts VALUES ('r', ?, ?)", [eid, k])
        for ci, wl, tokens in calls:
            c.execute("INSERT INTO calls VALUES ('r', ?, 'gpt-4o', 'recap', ?, 'ok', ?, ?, ?)", [eid, ci, latest, tokens, wl])
    # a failed call after e1's fill (ignored), and a react episode that never fills its window
    c.execute("INSERT INTO calls VALUES ('r', 'e1', 'gpt-4o', 'recap', 6, 'error', true, 99999, 6)")
    c.execute("INSERT INTO attempts VALUES ('r', 'x1', 64)")
    for ci, tokens in enumerate((100, 130, 160)):
        c.execute("INSERT INTO calls VALUES ('r', 'x1', 'gpt-4o', 'react', ?, 'ok', true, ?, ?)", [ci, tokens, 2 + 2 * ci])
    yield c
    c.close()


def test_growth_is_a_per_episode_slope_after_the_window_fills(con):
    rows = [
        dict(zip([d[0] for d in cur.description], r))
        for cur in [con.execute(load_sql("context_summary"))]
        for r in cur.fetchall()
    ]
    # recap slopes 14 (e1), 0 (e2), 25 (e3): median 14, quartiles 0 + 0.5 * 14 and 14 + 0.5 * 11
    assert_rows(
        rows,
        [
            {
                "model_label": "gpt-4o",
                "arm": "react",
                "episodes": 1,
                "calls": 3,
                "max_window_messages": 6,
                "filled_episodes": 0,
                "slope_median": None,
                "slope_q25": None,
                "slope_q75": None,
            },
            {
                "model_label": "gpt-4o",
                "arm": "recap",
                "episodes": 5,
                "calls": 20,
                "max_prompt_tokens": 900,
                "max_window_messages": 6,
                "filled_episodes": 3,
                "slope_median": 14.0,
                "slope_q25": 7.0,
                "slope_q75": 19.5,
            },
        ],
    )


def test_one_pooled_slope_would_have_said_otherwise(con):
    """Why per episode: over the same calls, one regression reads the pre-fill growth of e4 and e5."""
    points = [(ci, tokens) for _, _, calls, latest in EPISODES if latest for ci, _, tokens in calls]
    pooled = np.polyfit([x for x, _ in points], [y for _, y in points], 1)[0]
    assert pooled == pytest.approx(45.0857142857, rel=1e-9)  # more than 3x the per-episode median of 14
