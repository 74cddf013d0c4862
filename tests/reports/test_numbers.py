"""Every report query over the hand-written run A (and A+B) equals the number worked out by hand.

The expected values are derived in the comments from the rows in known_run.py; Wilson bounds and
McNemar p-values come from the independent reference formulas in reports.stats.
"""

from __future__ import annotations

import math
from fractions import Fraction

import pytest

from reports.stats import mcnemar_exact, paired_permutation_p, wilson
from reports.views import named_query, open_runs, run_query
from tests.reports.conftest import assert_rows

ALF = "alfworld/valid_unseen"
SYNC = "robotouille/synchronous"
TD = "scripted (test double)"


@pytest.fixture(scope="module")
def con_a(run_a):
    con = open_runs([run_a])
    yield con
    con.close()


def rate(model, arm, split, n, k, **extra):
    lo, hi = wilson(k, n)
    return {
        "model_label": model,
        "arm": arm,
        "env_split": split,
        "episodes": n,
        "successes": k,
        "success_rate": k / n,
        "ci_low": lo,
        "ci_high": hi,
        **extra,
    }


# react sync clusters by instance: i2 1/2 and i6 0/3. MSB = (1/2 - 1/5) / 1 = 0.3, MSW = (1 - 1/2) / 3
# = 1/6, m0 = 5 - 13/5 = 2.4, rho = (0.3 - 1/6) / (0.3 + 1.4/6) = 0.25, deff = 1 + (5/2 - 1) * 0.25
# = 1.375: Wilson at n_eff = 5 / 1.375 (recap's 2/2 and 2/3 give rho < 0 -> deff 1, plain Wilson)
REACT_SYNC_CI = dict(zip(("ci_low", "ci_high"), wilson(1 / 1.375, 5 / 1.375)))


def test_main_table(con_a):
    # sync: recap 4/5 (t6/84 agent_done), react 1/5 (only t2/42; t2/84 counts its attempt 2),
    # level_3 1/2 (t6/84 was cut by the cap: not finished, so in no rate); alfworld: one unit
    # each, the test double recap 1/2
    assert_rows(
        named_query(con_a, "success_by_split").dicts(),
        [
            rate("gpt-4o", "react", ALF, 1, 0, method="react", ablation="original"),
            rate("gpt-4o", "recap", ALF, 1, 1, method="recap", ablation="original"),
            rate(TD, "react", ALF, 1, 0),
            rate(TD, "recap", ALF, 2, 1),
            rate("gpt-4o", "react", SYNC, 5, 1, **REACT_SYNC_CI),
            rate("gpt-4o", "recap", SYNC, 5, 4),
            rate("gpt-4o", "recap[level_3]", SYNC, 2, 1, method="recap", ablation="level_3"),
        ],
    )


def test_wilson_bounds_by_hand(con_a):
    # 4/5: centre (0.8 + z^2/10) / (1 + z^2/5), the closed form in the paper's usual z = 1.96
    row = [r for r in named_query(con_a, "success_by_split").dicts() if r["arm"] == "recap" and r["env_split"] == SYNC][0]
    z = 1.959963984540054
    half = z * math.sqrt(0.8 * 0.2 / 5 + z * z / 100)
    assert row["ci_low"] == pytest.approx((0.8 + z * z / 10 - half) / (1 + z * z / 5), rel=1e-12)
    assert row["ci_high"] == pytest.approx((0.8 + z * z / 10 + half) / (1 + z * z / 5), rel=1e-12)
    assert (round(100 * row["ci_low"], 1), round(100 * row["ci_high"], 1)) == (37.6, 96.4)


def test_per_task_tables(con_a):
    def t(split, task, model, arm, n, k):
        r = rate(model, arm, split, n, k)
        r["task"] = task
        return r

    assert_rows(
        named_query(con_a, "success_by_task").dicts(),
        [
            t(ALF, "put", "gpt-4o", "react", 1, 0),
            t(ALF, "put", "gpt-4o", "recap", 1, 1),
            t(ALF, "put", TD, "react", 1, 0),
            t(ALF, "put", TD, "recap", 2, 1),
            t(SYNC, "t2", "gpt-4o", "react", 2, 1),
            t(SYNC, "t2", "gpt-4o", "recap", 2, 2),
            t(SYNC, "t6", "gpt-4o", "react", 3, 0),
            t(SYNC, "t6", "gpt-4o", "recap", 3, 2),
            t(SYNC, "t6", "gpt-4o", "recap[level_3]", 2, 1),
        ],
    )


def test_cross_model_table(con_a):
    def m(model, arm, n, k):
        r = rate(model, arm, "", n, k)
        del r["env_split"]
        return r

    assert_rows(
        named_query(con_a, "success_by_model").dicts(),
        [
            m("gpt-4o", "react", 6, 1),
            m("gpt-4o", "recap", 6, 5),
            m("gpt-4o", "recap[level_3]", 2, 1),
            m(TD, "react", 1, 0),
            m(TD, "recap", 2, 1),
        ],
    )


def test_ablation_table_pairs_with_original(con_a):
    def a(model, method, split, ablation, n, k, pairs=None, oo=None, vo=None, p=None):
        r = rate(
            model,
            "",
            split,
            n,
            k,
            method=method,
            ablation=ablation,
            window_size=64,
            pairs=pairs,
            original_only=oo,
            variant_only=vo,
            p_value=p,
        )
        del r["arm"]
        return r

    # level_3 vs original on the t6 seeds both finished, 42/126 (level_3's 84 was capped): original
    # S,S; level_3 F,S -> 1 discordant pair
    assert_rows(
        named_query(con_a, "success_by_ablation").dicts(),
        [
            a("gpt-4o", "react", ALF, "original", 1, 0),
            {**a("gpt-4o", "react", SYNC, "original", 5, 1), **REACT_SYNC_CI},
            a("gpt-4o", "recap", ALF, "original", 1, 1),
            a("gpt-4o", "recap", SYNC, "original", 5, 4),
            a("gpt-4o", "recap", SYNC, "level_3", 2, 1, 2, 1, 0, 1.0),
            a(TD, "react", ALF, "original", 1, 0),
            a(TD, "recap", ALF, "original", 2, 1),
        ],
    )


def test_paired_comparisons(con_a):
    rows = named_query(con_a, "paired_methods").dicts()
    assert_rows(
        rows,
        [
            {
                "model_label": "gpt-4o",
                "env_split": ALF,
                "arm_a": "react",
                "arm_b": "recap",
                "pairs": 1,
                "a_successes": 0,
                "b_successes": 1,
                "rate_diff": -1.0,
                "a_only": 0,
                "b_only": 1,
                "p_value": 1.0,
                "mean_cost_diff": -0.5,
                "cost_diffs": [-0.5],
            },
            {
                "model_label": TD,
                "env_split": ALF,
                "arm_a": "react",
                "arm_b": "recap",
                "pairs": 1,
                "a_successes": 0,
                "b_successes": 1,
                "rate_diff": -1.0,
                "a_only": 0,
                "b_only": 1,
                "p_value": 1.0,
                "mean_cost_diff": 0.0,
                "cost_diffs": [0.0],
            },
            # react vs recap on the 5 sync units: recap alone solved t2/84, t6/42, t6/126. The arms are
            # swapped per instance (all its seeds together): b_i - c_i = -1 (i2), -2 (i6); of the 4
            # patterns +-1 +-2 those with |sum| >= 3 are the 2 same-sign ones -> p = 2/4 (pairs treated
            # as independent gave 2/2^3 = 0.25)
            {
                "model_label": "gpt-4o",
                "env_split": SYNC,
                "arm_a": "react",
                "arm_b": "recap",
                "pairs": 5,
                "a_successes": 1,
                "b_successes": 4,
                "rate_diff": -0.6,
                "a_only": 0,
                "b_only": 3,
                "instances": 2,
                "p_value": 0.5,
                "mean_cost_diff": -1.65,
                "cost_diffs": [-0.5, -1.5, -2.0, -3.75, -0.5],
                "cost_instances": ["robotouille/synchronous/t2/i2"] * 2 + ["robotouille/synchronous/t6/i6"] * 3,
            },
            # level_3 finished t6/42 (F, $2) and t6/126 (S, $1): react $1.0/$1.5 both F, recap $3/$2 both S
            {
                "model_label": "gpt-4o",
                "env_split": SYNC,
                "arm_a": "react",
                "arm_b": "recap[level_3]",
                "pairs": 2,
                "a_successes": 0,
                "b_successes": 1,
                "rate_diff": -1 / 2,
                "a_only": 0,
                "b_only": 1,
                "p_value": 1.0,
                "mean_cost_diff": -0.25,
                "cost_diffs": [-1.0, 0.5],
            },
            {
                "model_label": "gpt-4o",
                "env_split": SYNC,
                "arm_a": "recap",
                "arm_b": "recap[level_3]",
                "pairs": 2,
                "a_successes": 2,
                "b_successes": 1,
                "rate_diff": 1 / 2,
                "a_only": 1,
                "b_only": 0,
                "p_value": 1.0,
                "mean_cost_diff": 1.0,
                "cost_diffs": [1.0, 1.0],
            },
        ],
    )
    # the 5 cost differences all have the same sign: pair by pair only the 2 all-same-sign patterns of 32
    # reach |sum| 8.25; flipping whole instances (i2 total -2.0, i6 -6.25) it is 2 of 4
    assert paired_permutation_p(rows[2]["cost_diffs"]) == 2 / 32
    assert paired_permutation_p(rows[2]["cost_diffs"], rows[2]["cost_instances"]) == 2 / 4


def test_costs(con_a):
    def c(model, arm, split, n, k, cost, sd, per_success, prompt, completion, tps, calls, calls_sd, cached, steps):
        return {
            "model_label": model,
            "arm": arm,
            "env_split": split,
            "episodes": n,
            "successes": k,
            "cost_usd": cost,
            "cost_per_episode": cost / n,
            "cost_sd": sd,
            "cost_per_success": per_success,
            "prompt_tokens_per_episode": prompt,
            "completion_tokens_per_episode": completion,
            "tokens_per_episode": prompt + completion,
            "tokens_per_success": tps,
            "calls_per_episode": calls,
            "calls_sd": calls_sd,
            "cached_share": cached,
            "steps_per_episode": steps,
        }

    assert_rows(
        named_query(con_a, "costs").dicts(),
        [
            c("gpt-4o", "react", ALF, 1, 0, 0.25, None, None, 100.0, 10.0, None, 2.0, None, 0.0, 1.0),
            c("gpt-4o", "recap", ALF, 1, 1, 0.75, None, 0.75, 300.0, 30.0, 330.0, 3.0, None, 0.0, 2.0),
            c(TD, "react", ALF, 1, 0, 0.0, None, None, 5000.0, 500.0, None, 10.0, None, 0.0, 4.0),
            c(TD, "recap", ALF, 2, 1, 0.0, 0.0, 0.0, 125.0, 12.5, 275.0, 1.5, math.sqrt(0.5), 0.0, 1.0),
            # react: $0.5, 0.5, 1.0, 0.25, 1.5 -> mean 0.75, sd sqrt(1.0 / 4); calls 3,2,4,3,6 -> sd sqrt(9.2 / 4)
            c("gpt-4o", "react", SYNC, 5, 1, 3.75, 0.5, 3.75, 380.0, 36.0, 2080.0, 3.6, math.sqrt(2.3), 100 / 1900, 2.4),
            # recap: $1, 2, 3, 4, 2 -> sd sqrt(5.2 / 4); calls 4, 8, 12, 16, 10 -> sd sqrt(80 / 4)
            c(
                "gpt-4o",
                "recap",
                SYNC,
                5,
                4,
                12.0,
                math.sqrt(1.3),
                3.0,
                1196.0,
                118.0,
                1642.5,
                10.0,
                math.sqrt(20),
                1700 / 5980,
                5.6,
            ),
            # level_3 finished t6/42 ($2, 900+90 tokens, 9 calls, 4 steps) and t6/126 ($1, 450+45, 5, 6)
            c("gpt-4o", "recap[level_3]", SYNC, 2, 1, 3.0, math.sqrt(0.5), 3.0, 675.0, 67.5, 1485.0, 7.0, math.sqrt(8), 0.0, 5.0),
        ],
    )


def test_spend_by_model_counts_every_call(con_a):
    # gpt-4o: recap t2/42 (4 calls, $1), react t2/84 attempt 1 ($1.125 with a failed call) and
    # attempt 2 ($0.5), react t6/84 ($0.25, two failed calls), a call with no episode row ($0.5)
    assert_rows(
        named_query(con_a, "spend_by_model").dicts(),
        [
            {
                "model_label": "gpt-4o",
                "calls": 12,
                "failed_calls": 3,
                "retries": 6,
                "prompt_tokens": 1480,
                "cached_prompt_tokens": 300,
                "completion_tokens": 110,
                "cached_share": 300 / 1480,
                "cost_usd": 3.375,
                "spend_share": 1.0,
            },
            {
                "model_label": TD,
                "calls": 2,
                "failed_calls": 0,
                "retries": 0,
                "prompt_tokens": 200,
                "cached_prompt_tokens": 0,
                "completion_tokens": 20,
                "cached_share": 0.0,
                "cost_usd": 0.0,
                "spend_share": 0.0,
            },
        ],
    )


def test_wasted_spend(con_a):
    def w(
        model, arm, calls, cost, failed, retries, failed_cost, repairs, repair_cost, superseded, orphan, failed_ep, wasted, share
    ):
        return {
            "model_label": model,
            "arm": arm,
            "calls": calls,
            "cost_usd": cost,
            "failed_calls": failed,
            "retries": retries,
            "failed_call_cost": failed_cost,
            "repair_calls": repairs,
            "repair_cost": repair_cost,
            "superseded_cost": superseded,
            "orphan_cost": orphan,
            "failed_episode_cost": failed_ep,
            "wasted_cost": wasted,
            "wasted_share": share,
        }

    assert_rows(
        named_query(con_a, "wasted_spend").dicts(),
        [
            w("gpt-4o", "(no episode row)", 1, 0.5, 0, 0, 0.0, 0, 0.0, 0.0, 0.5, 0.0, 0.5, 1.0),
            w("gpt-4o", "react", 7, 1.875, 3, 6, 0.125, 0, 0.0, 1.125, 0.0, 0.75, 1.875, 1.0),
            w("gpt-4o", "recap", 4, 1.0, 0, 0, 0.0, 1, 0.25, 0.0, 0.0, 0.0, 0.0, 0.0),
            w(TD, "recap", 2, 0.0, 0, 0, 0.0, 0, 0.0, 0.0, 0.0, 0.0, 0.0, None),
        ],
    )


def test_context_bound(con_a):
    def k(model, arm, ci, calls, mean, mx):
        return {
            "model_label": model,
            "arm": arm,
            "call_index": ci,
            "calls": calls,
            "mean_prompt_tokens": mean,
            "max_prompt_tokens": mx,
        }

    # react: attempt 2 of t2/84 (150, 150) and the one ok call of t6/84 (index 1: 100); failed
    # calls, superseded attempts and calls without an episode row are left out
    assert_rows(
        named_query(con_a, "context_by_call").dicts(),
        [
            k("gpt-4o", "react", 0, 1, 150.0, 150),
            k("gpt-4o", "react", 1, 2, 125.0, 150),
            k("gpt-4o", "recap", 0, 1, 100.0, 100),
            k("gpt-4o", "recap", 1, 1, 120.0, 120),
            k("gpt-4o", "recap", 2, 1, 140.0, 140),
            k("gpt-4o", "recap", 3, 1, 120.0, 120),
            k(TD, "recap", 0, 1, 100.0, 100),
            k(TD, "recap", 1, 1, 100.0, 100),
        ],
    )
    # recap: 100, 120, 140, 120 at x = 0..3: p95 = 120 + 0.85 * 20. No window reaches K = 64, so no
    # episode has a growth slope (tests/reports/test_stats_context.py checks those)
    assert_rows(
        named_query(con_a, "context_summary").dicts(),
        [
            {
                "model_label": "gpt-4o",
                "arm": "react",
                "calls": 3,
                "mean_prompt_tokens": 400 / 3,
                "median_prompt_tokens": 150.0,
                "p95_prompt_tokens": 150.0,
                "max_prompt_tokens": 150,
                "max_window_messages": 4,
                "episodes": 2,
                "filled_episodes": 0,
                "slope_median": None,
            },
            {
                "model_label": "gpt-4o",
                "arm": "recap",
                "calls": 4,
                "mean_prompt_tokens": 120.0,
                "median_prompt_tokens": 120.0,
                "p95_prompt_tokens": 137.0,
                "max_prompt_tokens": 140,
                "max_window_messages": 6,
                "episodes": 1,
                "filled_episodes": 0,
                "slope_median": None,
            },
            {
                "model_label": TD,
                "arm": "recap",
                "calls": 2,
                "mean_prompt_tokens": 100.0,
                "median_prompt_tokens": 100.0,
                "p95_prompt_tokens": 100.0,
                "max_prompt_tokens": 100,
                "max_window_messages": 4,
                "episodes": 1,
                "filled_episodes": 0,
                "slope_median": None,
            },
        ],
    )


def test_tree_statistics(con_a):
    # t2/42: depth 3 (levels 4); non-leaf nodes 0 (3 children), 1 (2), 4 (1): branching 6 / 3;
    # t6/42: depth 2; non-leaf 0 (2 children), 1 (1): branching 3 / 2
    assert_rows(
        run_query(con_a, "SELECT * FROM tree_stats ORDER BY episode_id").dicts(),
        [
            {
                "episode_id": "A-recap-t2-42",
                "nodes": 7,
                "max_depth": 3,
                "levels": 4,
                "internal_nodes": 3,
                "branching_factor": 2.0,
                "max_children": 3,
                "leaf_failures": 1,
                "primitive_nodes": 4,
                "refinements": 2,
            },
            {
                "episode_id": "A-recap-t6-42",
                "nodes": 4,
                "max_depth": 2,
                "levels": 3,
                "internal_nodes": 2,
                "branching_factor": 1.5,
                "max_children": 2,
                "leaf_failures": 0,
                "primitive_nodes": 2,
                "refinements": 0,
            },
        ],
    )
    assert_rows(
        named_query(con_a, "tree_summary").dicts(),
        [
            {
                "model_label": "gpt-4o",
                "arm": "recap",
                "env_split": SYNC,
                "episodes": 2,
                "mean_levels": 3.5,
                "mean_max_depth": 2.5,
                "max_depth_sd": math.sqrt(0.5),
                "mean_branching_factor": 1.75,
                "branching_factor_sd": math.sqrt(0.125),
                "max_children": 3,
                "nodes_per_episode": 5.5,
                "leaf_failures_per_episode": 0.5,
                "leaf_failures": 1,
                "refinements_per_episode": 1.0,
            },
        ],
    )
    assert [tuple(r[2:]) for r in named_query(con_a, "tree_distribution").rows] == [
        ("branching_factor", 1, 1),
        ("branching_factor", 2, 1),
        ("leaf_failures", 0, 1),
        ("leaf_failures", 1, 1),
        ("levels", 3, 1),
        ("levels", 4, 1),
    ]


def test_nodes_view_latest_version(con_a):
    rows = run_query(
        con_a,
        "SELECT node_id, n_children, is_leaf, n_versions, think, subtasks FROM nodes WHERE episode_id = 'A-recap-t2-42' ORDER BY node_id",
    ).rows
    assert rows[0] == (0, 3, False, 2, "onion done", ["serve", "clean"])
    assert rows[6] == (6, 0, True, 1, None, ["place onion on table9"])


def test_step_patterns(con_a):
    assert run_query(con_a, "SELECT * EXCLUDE (run_id) FROM step_patterns ORDER BY episode_id").rows == [
        ("A-lvl3-t6-42", 4, 0, 0, 0, False, False, None),  # same action, observation changes: progress
        ("A-react-t2-84-a2", 6, 0, 0, 0, False, True, 2),  # a-b-a-b-a-b
        ("A-react-t6-126", 4, 2, 1, 2, False, False, None),  # invalid twice, never in a row
        ("A-react-t6-42", 4, 3, 3, 1, True, False, None),  # three invalid in a row
        ("A-recap-t2-42", 3, 1, 1, 1, False, False, None),
        ("A-recap-t6-84", 3, 0, 0, 0, False, False, None),  # same step 3 times: one short of a loop
    ]


def test_failure_mode_of_every_episode(con_a):
    modes = dict(run_query(con_a, "SELECT episode_id, mode FROM episode_modes").rows)
    assert modes == {
        "A-recap-t2-42": "success",
        "A-recap-t2-84": "success",
        "A-recap-t6-42": "success",
        "A-recap-t6-84": "agent_done_early",
        "A-recap-t6-126": "success",
        "A-react-t2-42": "success",
        "A-react-t2-84-a2": "repeated_action_loop",
        "A-react-t6-42": "invalid_action_loop",
        "A-react-t6-84": "model_error:rate_limit",
        "A-react-t6-126": "call_cap",
        "A-lvl3-t6-42": "step_cap",
        "A-lvl3-t6-84": "budget_exhausted",
        "A-lvl3-t6-126": "success",
        "A-recap-alf-p1": "success",
        "A-react-alf-p1": "json_failures",
        "A-recap-alf-p1-td": "success",
        "A-recap-alf-p2-td": "env_error",
        "A-react-alf-p1-td": "episode_limit",
    }
    # failures: the finished units that did not succeed (the capped level_3 t6/84 is not one)
    assert run_query(con_a, "SELECT count(*) FROM failures").rows == [(9,)]


def test_failure_modes_table(con_a):
    def f(model, mode, n, share, cost, steps, calls, examples):
        return {
            "model_label": model,
            "mode": mode,
            "episodes": n,
            "share": share,
            "cost_usd": cost,
            "mean_steps": steps,
            "mean_calls": calls,
            "examples": examples,
        }

    assert_rows(
        named_query(con_a, "failure_modes").dicts(),
        [
            # the 14 finished gpt-4o units (level_3 t6/84, capped, is in the coverage table instead)
            f("gpt-4o", "success", 7, 7 / 14, 10.25, 36 / 7, 45 / 7, ["A-lvl3-t6-126", "A-react-t2-42", "A-recap-alf-p1"]),
            f("gpt-4o", "agent_done_early", 1, 1 / 14, 4.0, 3.0, 16.0, ["A-recap-t6-84"]),
            f("gpt-4o", "call_cap", 1, 1 / 14, 1.5, 2.0, 6.0, ["A-react-t6-126"]),
            f("gpt-4o", "invalid_action_loop", 1, 1 / 14, 1.0, 1.0, 4.0, ["A-react-t6-42"]),
            f("gpt-4o", "json_failures", 1, 1 / 14, 0.25, 1.0, 2.0, ["A-react-alf-p1"]),
            f("gpt-4o", "model_error:rate_limit", 1, 1 / 14, 0.25, 0.0, 3.0, ["A-react-t6-84"]),
            f("gpt-4o", "repeated_action_loop", 1, 1 / 14, 0.5, 6.0, 2.0, ["A-react-t2-84-a2"]),
            f("gpt-4o", "step_cap", 1, 1 / 14, 2.0, 4.0, 9.0, ["A-lvl3-t6-42"]),
            f(TD, "env_error", 1, 1 / 3, 0.0, 0.0, 1.0, ["A-recap-alf-p2-td"]),
            f(TD, "episode_limit", 1, 1 / 3, 0.0, 4.0, 10.0, ["A-react-alf-p1-td"]),
            f(TD, "success", 1, 1 / 3, 0.0, 2.0, 2.0, ["A-recap-alf-p1-td"]),
        ],
    )
    by_arm = named_query(con_a, "failure_modes_by_arm").rows
    assert [r[:4] for r in by_arm if r[1] == "recap[level_3]"] == [
        ("gpt-4o", "recap[level_3]", "step_cap", 1),
        ("gpt-4o", "recap[level_3]", "success", 1),
    ]


def test_overview_and_runs(con_a):
    assert named_query(con_a, "overview").dicts() == [
        {
            "run_folders": 1,
            "runs": 1,
            "attempts": 19,
            "units": 18,
            "finished_units": 17,
            "successes": 8,
            "test_double_units": 3,
            "llm_calls": 14,
            "spend_usd": 3.375,
            "steps": 24,
            "skipped_part_files": 0,
        }
    ]
    assert named_query(con_a, "runs").rows == [("runA", 2, "1970-01-01 00:16:40 UTC", "hostA2", "abc123", "hashA", 5, 18, 8)]
    assert named_query(con_a, "events_summary").rows == [
        ("gateway", "retry", "warning", 2, 2),
        ("pipeline", "worker_restart", "error", 1, 0),
    ]


def test_two_runs_together(run_a, run_b):
    con = open_runs([run_a, run_b])
    rows = {
        (r["model_label"], r["arm"], r["env_split"]): (r["successes"], r["episodes"])
        for r in named_query(con, "success_by_split").dicts()
    }
    # run B re-runs react t6/42 (same unit id, attempt 2: success) and adds recap with a 128 window,
    # so recap arms carry their window size. A unit is (run, unit id): run B's row does not replace
    # run A's failure (another run, not another attempt), both count
    assert rows == {
        ("gpt-4o", "react", ALF): (0, 1),
        ("gpt-4o", "recap ctx 64", ALF): (1, 1),
        (TD, "react", ALF): (0, 1),
        (TD, "recap ctx 64", ALF): (1, 2),
        ("gpt-4o", "react", SYNC): (2, 6),
        ("gpt-4o", "recap ctx 64", SYNC): (4, 5),
        ("gpt-4o", "recap ctx 128", SYNC): (1, 1),
        ("gpt-4o", "recap[level_3]", SYNC): (1, 2),
    }
    assert run_query(
        con, "SELECT run_id, episode_id, is_latest FROM attempts WHERE unit_id LIKE 'react-dflt-gpt-4o-sync-t6-i6-42' ORDER BY 1"
    ).rows == [("runA", "A-react-t6-42", True), ("runB", "B-react-t6-42-a2", True)]
    assert named_query(con, "overview").rows[0][:6] == (2, 2, 21, 20, 19, 10)
    con.close()


def test_macros_match_reference_formulas(con_a):
    for k, n in [(0, 1), (1, 1), (3, 7), (10, 20), (19, 20), (134, 134)]:
        lo, hi = run_query(con_a, f"SELECT wilson_low({k}, {n}), wilson_high({k}, {n})").rows[0]
        assert (lo, hi) == pytest.approx(wilson(k, n), rel=1e-12, abs=1e-15)
    assert run_query(con_a, "SELECT wilson_low(0, 0)").rows == [(None,)]
    for b in range(13):
        for c in range(13):
            (p,) = run_query(con_a, f"SELECT mcnemar_p({b}, {c})").rows[0]
            assert p == pytest.approx(float(mcnemar_exact(b, c)), rel=1e-12), (b, c)
    assert mcnemar_exact(0, 3) == Fraction(1, 4)
    assert mcnemar_exact(1, 5) == Fraction(14, 64)


def test_permutation_test_exact_and_sampled():
    assert paired_permutation_p([1.0, 2.0, 3.0]) == 2 / 8  # |sum| 6 only for all +/all -
    assert paired_permutation_p([1.0, 2.0, -3.0]) == 8 / 8  # observed 0
    assert paired_permutation_p([0.0, 0.0]) == 1.0
    assert paired_permutation_p([2.0, 0.0, 0.0]) == 1.0  # one non-zero difference: both signs tie
    # 30 equal positive differences: no random sign pattern of 20,000 reaches |sum| 30 (chance 2^-29)
    assert paired_permutation_p([1.0] * 30) == 1 / 20001
    sampled = paired_permutation_p([1.0, -0.5] * 12)
    assert sampled == paired_permutation_p([1.0, -0.5] * 12)  # fixed seed: reproducible
    assert 0 < sampled <= 1


def test_loop_detector_boundaries(tmp_path):
    """Cycles must repeat 3 times back to back (a single action 4 times); progress is no loop."""
    from schemas.parts import PartWriter
    from schemas.records import StepRecord

    obs = {"a": "at a", "b": "at b", "c": "at c", "x": "same", "ok": "o", "bad": "o"}
    episodes = {
        "e1-abc-x3": ["a", "b", "c"] * 3,
        "e2-abc-short": (["a", "b", "c"] * 3)[:8],
        "e3-x-x4": ["x"] * 4,
        "e4-ab-x2.5": ["a", "b", "a", "b", "a"],
        "e5-bad-x3": ["bad", "ok", "bad", "ok", "bad"],
    }
    rows = [
        StepRecord(eid, i, i, a, a != "bad", obs[a], False, False)
        for eid, actions in episodes.items()
        for i, a in enumerate(actions)
    ]
    rows += [StepRecord("e6-progress", i, i, "cut", True, f"cut {i}/6", False, False) for i in range(6)]
    PartWriter(tmp_path).write_records("r", rows)
    (tmp_path / "run.json").write_text('{"run_id": "r"}')
    con = open_runs([tmp_path])
    got = run_query(
        con,
        "SELECT episode_id, longest_invalid_run, max_same_invalid, invalid_loop, loop_cycle_len FROM step_patterns ORDER BY episode_id",
    ).rows
    assert got == [
        ("e1-abc-x3", 0, 0, False, 3),
        ("e2-abc-short", 0, 0, False, None),
        ("e3-x-x4", 0, 0, False, 1),
        ("e4-ab-x2.5", 0, 0, False, None),
        ("e5-bad-x3", 1, 3, True, None),
        ("e6-progress", 0, 0, False, None),
    ]


def test_a_window_that_differs_only_between_benchmarks_keeps_one_arm(tmp_path):
    """The released ReAct keeps 64 messages on Robotouille and 128 on ALFWorld: one protocol, one
    arm; two windows on one benchmark are two variants (``ctx N``) on every benchmark."""
    import dataclasses

    from recap.config import AgentConfig, build_config
    from schemas.parts import PartWriter
    from tests.doubles.known_run import ALF as ALF_BENCH
    from tests.doubles.known_run import REACT, episode
    from tests.doubles.known_run import SYNC as SYNC_BENCH

    kw = {"cost": 0.1, "prompt": 10, "cached": 0, "completion": 1, "calls": 1, "steps": 1}

    def row(eid: str, method: str, window: int, bench: tuple[str, str], task: str) -> object:
        r = episode(eid, method, REACT, "gpt-4o", bench, task, f"{task}-1", 0, "success", **kw)
        cfg = build_config(AgentConfig, window=window).to_json()
        return dataclasses.replace(r, unit_id=eid, method_config=cfg)

    rows = [
        row("react-sync", "react", 64, SYNC_BENCH, "t2"),
        row("react-alf", "react", 128, ALF_BENCH, "heat"),
        row("recap-sync-64", "recap", 64, SYNC_BENCH, "t2"),
        row("recap-sync-128", "recap", 128, SYNC_BENCH, "t3"),
        row("recap-alf", "recap", 128, ALF_BENCH, "heat"),
    ]
    run = tmp_path / "runC"
    run.mkdir()
    (run / "run.json").write_text('{"run_id": "runC", "spec_hash": "hashC"}')
    PartWriter(run, writer="sink0001").write_records("runC", rows)
    con = open_runs([run])
    got = sorted(run_query(con, "SELECT episode_id, arm FROM attempts").rows)
    con.close()
    assert got == [
        ("react-alf", "react"),
        ("react-sync", "react"),
        ("recap-alf", "recap ctx 128"),
        ("recap-sync-128", "recap ctx 128"),
        ("recap-sync-64", "recap ctx 64"),
    ]
