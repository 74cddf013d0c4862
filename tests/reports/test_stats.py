"""reports/stats.py and the SQL macros it mirrors: Holm's adjustment, the clamped Wilson interval,
the instance-clustered Wilson interval and the paired tests that permute whole instances (the
cost sign-flip test and the clustered McNemar test), each against hand-computed values and an
independent computation (the step-down procedure itself; ANOVA from the raw 0/1 data; the score
test solved by bisection; every sign pattern listed); and the notes' words for them."""

from __future__ import annotations

import itertools
import math
import random
from fractions import Fraction

import duckdb
import numpy as np
import pytest

from reports.stat_notes import interval_note, mcnemar_note, permutation_note
from reports.stats import (
    SAMPLES,
    SEED,
    Z95,
    SignFlipTest,
    cluster_totals,
    cluster_wilson,
    clustered_mcnemar_exact,
    clustered_permutation_test,
    comparisons,
    design_effect,
    holm,
    instance_discordance,
    mcnemar_exact,
    paired_permutation_p,
    sign_flip_test,
    wilson,
)
from reports.views import load_sql, split_statements


@pytest.fixture(scope="module")
def con():
    c = duckdb.connect(":memory:")
    for statement in split_statements(load_sql("macros")):
        c.execute(statement)
    yield c
    c.close()


# -- Holm -------------------------------------------------------------------------------------------


def test_holm_by_hand():
    # sorted 1/128, 1/64, 3/64, 1/16 (m = 4): 4/128, 3/64, max(3/64, 6/64), max(6/64, 1/16)
    assert holm([1 / 64, 1 / 16, 3 / 64, 1 / 128]) == [3 / 64, 6 / 64, 6 / 64, 4 / 128]
    # None is no test: it stays None and m = 2
    assert holm([None, 0.25, 0.5]) == [None, 0.5, 0.5]
    # capped at 1; ties keep their order
    assert holm([0.5, 0.75]) == [1.0, 1.0]
    assert holm([0.125, 0.125]) == [0.25, 0.25]
    assert holm([0.03125]) == [0.03125]
    assert holm([]) == []
    assert holm([float("nan"), 0.25]) == [None, 0.25]
    assert comparisons([None, 0.25, float("nan"), 1.0]) == 2


def _step_down_rejections(pvalues: list[float], alpha: float) -> set[int]:
    """Holm's procedure as he states it: compare p(i) with alpha / (m - i + 1) in ascending order
    and stop at the first that is not smaller or equal."""
    order = sorted(range(len(pvalues)), key=lambda i: pvalues[i])
    m = len(pvalues)
    out = set()
    for rank, i in enumerate(order):
        if pvalues[i] > alpha / (m - rank):
            break
        out.add(i)
    return out


def test_holm_adjusted_p_rejects_exactly_what_the_step_down_procedure_rejects():
    rng = random.Random(7)
    for _ in range(300):
        ps = [rng.choice([rng.random(), rng.random() / 50, 0.01]) for _ in range(rng.randint(1, 9))]
        adjusted = holm(ps)
        for alpha in (0.001, 0.01, 0.05, 0.1, 0.2):
            assert {i for i, a in enumerate(adjusted) if a <= alpha} == _step_down_rejections(ps, alpha), (ps, alpha)


# -- Wilson, clamped ------------------------------------------------------------------------------


def test_wilson_bounds_are_clamped_to_0_and_1(con):
    for n in range(1, 201):
        assert wilson(0, n)[0] == 0.0 and wilson(n, n)[1] == 1.0
        assert con.execute(f"SELECT wilson_low(0, {n}), wilson_high({n}, {n})").fetchone() == (0.0, 1.0)
    assert con.execute("SELECT wilson_low(0, 0), wilson_high(0, 0)").fetchone() == (None, None)
    with pytest.raises(ValueError, match="^wilson interval needs n > 0$"):
        wilson(0, 0)


# -- clustered Wilson -------------------------------------------------------------------------------


def test_design_effect_by_hand():
    # i2 1/2 and i6 0/3: MSB = 0.3, MSW = 1/6, m0 = 2.4, rho = 0.25, deff = 1 + 1.5 * 0.25
    assert design_effect([(1, 2), (0, 3)]) == pytest.approx(1.375, rel=1e-12)
    # seeds that always agree: rho = 1, deff = m = 3; two instances count as two trials
    assert design_effect([(3, 3), (0, 3)]) == pytest.approx(3.0, rel=1e-12)
    assert cluster_wilson([(3, 3), (0, 3)]) == pytest.approx(wilson(1, 2), rel=1e-12)
    # one episode per instance, one instance, no variation, or seeds that disagree more than
    # instances do (rho < 0): deff 1, the plain Wilson interval exactly
    for clusters in ([(1, 1), (0, 1), (1, 1)], [(2, 5)], [(0, 3), (0, 2)], [(3, 3), (2, 2)], [(1, 2), (1, 2)], [(2, 2), (2, 3)]):
        assert design_effect(clusters) == 1.0, clusters
        k, n = sum(y for y, _ in clusters), sum(m for _, m in clusters)
        assert cluster_wilson(clusters) == wilson(k, n)


def _anova_deff(clusters: list[tuple[int, int]]) -> float:
    """Kish's deff from the raw 0/1 observations: one-way ANOVA sums of squares by numpy."""
    groups = [np.array([1.0] * y + [0.0] * (m - y)) for y, m in clusters]
    allv = np.concatenate(groups)
    n, g = allv.size, len(groups)
    ssb = sum(v.size * (v.mean() - allv.mean()) ** 2 for v in groups)
    ssw = sum(((v - v.mean()) ** 2).sum() for v in groups)
    msb, msw = ssb / (g - 1), ssw / (n - g)
    m0 = (n - sum(v.size**2 for v in groups) / n) / (g - 1)
    rho = max(0.0, (msb - msw) / (msb + (m0 - 1) * msw)) if msb + (m0 - 1) * msw > 0 else 0.0
    return 1 + (n / g - 1) * rho


def _score_interval(p: float, n: float, z: float = Z95) -> tuple[float, float]:
    """Wilson's interval as its definition: the pi with |p - pi| <= z sqrt(pi (1 - pi) / n),
    found by bisection on each side of p."""

    def inside(pi: float) -> bool:
        return (p - pi) ** 2 <= z * z * pi * (1 - pi) / n

    def edge(a: float, b: float) -> float:  # inside(a) != inside(b)
        for _ in range(200):
            mid = (a + b) / 2
            a, b = (mid, b) if inside(mid) == inside(a) else (a, mid)
        return (a + b) / 2

    lo = 0.0 if inside(0.0) else edge(p, 0.0)
    hi = 1.0 if inside(1.0) else edge(p, 1.0)
    return lo, hi


def _random_clusters(rng: random.Random) -> list[tuple[int, int]]:
    out = []
    for _ in range(rng.randint(2, 12)):
        m = rng.randint(1, 6)
        bias = rng.random()
        out.append((sum(rng.random() < bias for _ in range(m)), m))
    return out


def test_clustered_wilson_against_an_independent_computation():
    rng = random.Random(20251)
    for _ in range(200):
        clusters = _random_clusters(rng)
        n = sum(m for _, m in clusters)
        k = sum(y for y, _ in clusters)
        if n == len(clusters) or k in (0, n):
            assert design_effect(clusters) == 1.0
            continue
        deff = _anova_deff(clusters)
        assert design_effect(clusters) == pytest.approx(deff, rel=1e-9, abs=1e-12), clusters
        lo, hi = cluster_wilson(clusters)
        ref = _score_interval(k / n, n / deff)
        assert (lo, hi) == pytest.approx(ref, abs=1e-9), clusters
        assert deff >= 1.0 and lo <= wilson(k, n)[0] + 1e-12 and hi >= wilson(k, n)[1] - 1e-12  # never narrower


def test_sql_macros_match_the_python_reference(con):
    rng = random.Random(5)
    cases = [[(1, 2), (0, 3)], [(3, 3), (0, 3)], [(1, 1), (0, 1)], [(2, 5)]] + [_random_clusters(rng) for _ in range(40)]
    rows = [(case, f"i{c}", j < y) for case, clusters in enumerate(cases) for c, (y, m) in enumerate(clusters) for j in range(m)]
    con.execute("CREATE OR REPLACE TEMP TABLE cases (case_id INTEGER, inst VARCHAR, success BOOLEAN)")
    con.executemany("INSERT INTO cases VALUES (?, ?, ?)", rows)
    got = con.execute(
        "SELECT case_id, instance_deff(obs), cluster_wilson_low(obs), cluster_wilson_high(obs) "
        "FROM (SELECT case_id, list({'instance': inst, 'success': success}) AS obs FROM cases GROUP BY case_id) ORDER BY case_id"
    ).fetchall()
    assert [r[0] for r in got] == list(range(len(cases)))
    for (_, deff, lo, hi), clusters in zip(got, cases):
        assert deff == pytest.approx(design_effect(clusters), rel=1e-12), clusters
        assert (lo, hi) == pytest.approx(cluster_wilson(clusters), rel=1e-12, abs=1e-15), clusters
    # episode_obs keys instances by benchmark, split, task and instance id; an empty list has no interval
    key = con.execute("SELECT episode_obs('robotouille', 'synchronous', 't6', 'i6', true)").fetchone()[0]
    assert key == {"instance": "robotouille/synchronous/t6/i6", "success": True}
    assert con.execute("SELECT cluster_wilson_low([]::STRUCT(instance VARCHAR, success BOOLEAN)[])").fetchone() == (None,)


def test_sql_clustered_interval_in_a_grouped_query(con):
    """As the success tables use it: one list per group, the instance as the cluster."""
    rows = [("a", "i1", True), ("a", "i1", True), ("a", "i2", False), ("a", "i2", False), ("b", "i1", True), ("b", "i2", False)]
    con.execute("CREATE OR REPLACE TEMP TABLE eps (arm VARCHAR, inst VARCHAR, success BOOLEAN)")
    con.executemany("INSERT INTO eps VALUES (?, ?, ?)", rows)
    got = con.execute(
        "SELECT arm, cluster_wilson_low(list({'instance': inst, 'success': success})), "
        "cluster_wilson_high(list({'instance': inst, 'success': success})) FROM eps GROUP BY arm ORDER BY arm"
    ).fetchall()
    # a: seeds agree within each instance -> deff 2, two effective trials; b: one episode each
    assert got[0][1:] == pytest.approx(wilson(1, 2), rel=1e-12)
    assert got[1][1:] == pytest.approx(wilson(1, 2), rel=1e-12)
    assert not math.isclose(got[0][1], wilson(2, 4)[0])


# -- paired tests that permute whole instances -------------------------------------------------------
#
# Reference: every sign pattern listed with itertools and counted in exact arithmetic.


def _brute_force_p(totals: list[Fraction]) -> Fraction:
    nz = [t for t in totals if t != 0]
    observed = abs(sum(nz, Fraction(0)))
    hits = sum(1 for s in itertools.product((1, -1), repeat=len(nz)) if abs(sum(x * t for x, t in zip(s, nz))) >= observed)
    return Fraction(hits, 2 ** len(nz))


#: the issue's run: 6 instances x 3 seeds, arm A cheaper on every one of the 18 paired units
SIX_BY_THREE_COST = [
    -0.25,
    -0.5,
    -1.0,
    -0.75,
    -0.5,
    -0.25,
    -2.0,
    -0.5,
    -1.5,
    -0.125,
    -0.25,
    -0.375,
    -1.0,
    -1.0,
    -1.0,
    -3.0,
    -0.5,
    -0.5,
]
SIX_BY_THREE_INSTANCES = [f"i{i}" for i in range(1, 7) for _ in range(3)]


def test_cost_permutation_flips_whole_instances_the_issue_example():
    # pair by pair all 18 differences have one sign: 2 of 2^18 patterns reach |sum| (the report printed
    # 0.0001 when it sampled them); with the 6 instances flipped as units it is 2 of 2^6
    t = clustered_permutation_test(SIX_BY_THREE_COST, SIX_BY_THREE_INSTANCES)
    assert t == SignFlipTest(2 / 64, 6, True, 64, None)
    assert t.p == 0.03125
    assert clustered_permutation_test(SIX_BY_THREE_COST) == SignFlipTest(2 / 2**18, 18, True, 2**18, None)
    # the pairs' order does not matter, only which instance each belongs to
    order = list(range(18))
    random.Random(3).shuffle(order)
    assert paired_permutation_p([SIX_BY_THREE_COST[i] for i in order], [SIX_BY_THREE_INSTANCES[i] for i in order]) == 2 / 64


def test_cost_permutation_by_hand_with_mixed_signs():
    # instance totals -1.75 (i1: -1, -1, +0.25), +0.5 (i2), -0.5 (i3: -1, +0.5), 0 (i4: +1, -1, dropped):
    # sum -1.75; of the 8 patterns +-1.75 +-0.5 +-0.5 those with |sum| >= 1.75: all with 1.75's sign
    # against... 1.75 + 0.5 + 0.5 = 2.75, 1.75 + 0.5 - 0.5 = 1.75 (twice), 1.75 - 1 = 0.75 -> 3 of 4, x2 signs
    diffs = [-1.0, -1.0, 0.25, 0.5, -1.0, 0.5, 1.0, -1.0]
    keys = ["i1", "i1", "i1", "i2", "i3", "i3", "i4", "i4"]
    assert cluster_totals(diffs, keys) == [-1.75, 0.5, -0.5, 0.0]
    assert clustered_permutation_test(diffs, keys) == SignFlipTest(6 / 8, 3, True, 8, None)
    assert paired_permutation_p([0.0, 0.0], ["a", "b"]) == 1.0
    assert paired_permutation_p([1.0, -1.0], ["a", "a"]) == 1.0  # one instance, total 0
    assert paired_permutation_p([1.0, float("nan"), None], ["a", "b", "c"]) == 1.0  # one instance left: both signs tie
    with pytest.raises(ValueError, match="^3 differences but 2 cluster keys$"):
        cluster_totals([1.0, 2.0, 3.0], ["a", "b"])


def test_cost_permutation_with_one_seed_per_instance_is_the_ordinary_sign_flip_test():
    rng = random.Random(11)
    for _ in range(60):
        n = rng.randint(1, 12)
        diffs = [rng.choice([0.0, rng.uniform(-3, 3), float(rng.randint(-3, 3))]) for _ in range(n)]
        keys = [f"i{j}" for j in range(n)]
        assert clustered_permutation_test(diffs, keys) == clustered_permutation_test(diffs)
        want = _brute_force_p([Fraction(d) for d in diffs])
        assert paired_permutation_p(diffs, keys) == pytest.approx(float(want), abs=1e-15), diffs


def test_cost_permutation_exact_up_to_20_instances_against_full_enumeration():
    rng = np.random.default_rng(5)
    for k in (1, 2, 7, 13, 17):  # the same split-in-halves code counts 2^20
        totals = rng.normal(size=k).round(2)
        totals[0] = -abs(totals[1:]).sum() * 0.3 if k > 1 else totals[0]
        signs = ((np.arange(2**k)[:, None] >> np.arange(k)[None, :]) & 1) * 2 - 1
        sums = np.abs(signs.astype(np.float64) @ totals)
        observed = abs(totals.sum())
        want = np.count_nonzero(sums >= observed - 1e-9 * max(1.0, observed)) / 2**k
        got = sign_flip_test(list(totals))
        assert (got.p, got.units, got.exact, got.patterns) == (want, k, True, 2**k)


def test_cost_permutation_samples_above_20_instances_with_a_fixed_reported_seed():
    t = sign_flip_test([1.0] * 21)
    assert (t.units, t.exact, t.patterns, t.seed) == (21, False, SAMPLES, SEED) == (21, False, 20_000, 20251)
    # with this seed 1 of the 20,000 random patterns of 21 signs is all one sign (expected 20,000 / 2^20 = 0.02):
    # (1 + 1) / (20,000 + 1)
    assert t.p == 2 / 20_001
    assert sign_flip_test([1.0] * 30).p == 1 / 20_001  # none of 30: (0 + 1) / (m + 1)
    many = [((-1) ** j) * (1 + j % 5) + 0.5 for j in range(40)]
    assert sign_flip_test(many) == sign_flip_test(many)  # reproducible
    assert sign_flip_test(many, seed=1).seed == 1
    # per instance: 40 pairs in 8 instances are enumerated exactly again
    assert clustered_permutation_test(many, [j // 5 for j in range(40)]).exact


# -- clustered McNemar ----------------------------------------------------------------------------------


def _pairs_6x3() -> list[tuple[str, bool, bool]]:
    """6 instances x 3 seeds: (instance, A solved, B solved) per paired unit.

    i1: A alone 3 times (D = 3); i2: A alone twice, both once (2); i3: A alone twice, neither once (2);
    i4: A alone once (1); i5: B alone once (-1); i6: A alone once and B alone once (0).
    b = 9 units only A solved, c = 2 only B."""
    rows = {
        "i1": [(1, 0), (1, 0), (1, 0)],
        "i2": [(1, 0), (1, 0), (1, 1)],
        "i3": [(1, 0), (1, 0), (0, 0)],
        "i4": [(1, 0), (0, 0), (1, 1)],
        "i5": [(0, 1), (0, 0), (1, 1)],
        "i6": [(1, 0), (0, 1), (0, 0)],
    }
    return [(i, bool(a), bool(b)) for i, units in rows.items() for a, b in units]


def test_clustered_mcnemar_by_hand_6_instances_x_3_seeds():
    pairs = _pairs_6x3()
    d = instance_discordance([a for _, a, _ in pairs], [b for _, _, b in pairs], [i for i, _, _ in pairs])
    assert d == [3, 2, 2, 1, -1, 0]
    # |D| = 3, 2, 2, 1, 1 (sum 9), observed |sum D| = 7. Flipping a subset F gives 9 - 2 sum(F): at least 7
    # in absolute value when sum(F) <= 1 ({}, {1}, {1'}) or >= 8 (their complements): 6 of 2^5
    assert clustered_mcnemar_exact(d) == Fraction(6, 32)
    # the pairs taken as independent: b = 9, c = 2 -> 2 (1 + 11 + 55) / 2^11
    assert mcnemar_exact(9, 2) == Fraction(134, 2048)
    assert clustered_mcnemar_exact(d) == _brute_force_p([Fraction(x) for x in d])


def test_clustered_mcnemar_with_one_seed_per_instance_is_the_exact_mcnemar_test(con):
    for b in range(13):
        for c in range(13):
            d = [1] * b + [-1] * c + [0] * 3
            assert clustered_mcnemar_exact(d) == mcnemar_exact(b, c), (b, c)
            (sql,) = con.execute("SELECT sign_flip_int_p(?)", [d]).fetchone()
            (plain,) = con.execute(f"SELECT mcnemar_p({b}, {c})").fetchone()
            assert sql == pytest.approx(plain, rel=1e-12) and sql == pytest.approx(float(mcnemar_exact(b, c)), rel=1e-12)


def _sql_pairs(con, pairs: list[tuple[str, bool, bool]]) -> float:
    (p,) = con.execute(
        "SELECT clustered_mcnemar_p(list(pair_obs('robotouille', 'synchronous', 't6', inst, a, b))) "
        "FROM (SELECT unnest(?::STRUCT(inst VARCHAR, a BOOLEAN, b BOOLEAN)[], recursive := true))",
        [[{"inst": i, "a": a, "b": b} for i, a, b in pairs]],
    ).fetchone()
    return p


def test_clustered_mcnemar_sql_macro_agrees_with_the_reference(con):
    assert _sql_pairs(con, _pairs_6x3()) == pytest.approx(6 / 32, rel=1e-12)
    rng = random.Random(17)
    for case in range(40):
        k = rng.choice([1, 2, 5, 9, 20, 35, 80])  # beyond 20 instances too: both are exact for any k
        pairs = []
        for i in range(k):
            for _ in range(rng.randint(1, 4)):
                pairs.append((f"i{i}", rng.random() < 0.6, rng.random() < 0.4))
        d = instance_discordance([a for _, a, _ in pairs], [b for _, _, b in pairs], [i for i, _, _ in pairs])
        assert _sql_pairs(con, pairs) == pytest.approx(float(clustered_mcnemar_exact(d)), rel=1e-12), case
    assert con.execute("SELECT clustered_mcnemar_p([]::STRUCT(instance VARCHAR, d INTEGER)[])").fetchone() == (1.0,)


def test_paired_methods_query_tests_per_instance():
    """paired_methods.sql over a hand-made outcomes table of 6 instances x 3 seeds: the McNemar p is
    the clustered one, and cost_diffs / cost_instances give the per-instance cost test."""
    c = duckdb.connect(":memory:")
    for statement in split_statements(load_sql("macros")):
        c.execute(statement)
    rows = []
    for j, (inst, a, b) in enumerate(_pairs_6x3()):
        seed = j % 3
        for arm, ok, cost in (("a", a, 1.0), ("b", b, 1.0 - SIX_BY_THREE_COST[j])):
            rows.append(("r", "m", "robotouille/synchronous", arm, "robotouille", "synchronous", "t6", inst, seed, ok, cost, 1.0))
    # one run (a unit is (run, unit id): the query pairs within a run first)
    c.execute(
        "CREATE TABLE outcomes (run_id VARCHAR, model_label VARCHAR, env_split VARCHAR, arm VARCHAR, benchmark VARCHAR, split VARCHAR, "
        "task VARCHAR, instance_id VARCHAR, sampling_seed BIGINT, success BOOLEAN, cost_usd DOUBLE, ended_at DOUBLE)"
    )
    c.executemany("INSERT INTO outcomes VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)", rows)
    cur = c.execute(load_sql("paired_methods"))
    names = [d[0] for d in cur.description]
    (row,) = [dict(zip(names, r)) for r in cur.fetchall()]
    assert (row["pairs"], row["instances"], row["a_only"], row["b_only"]) == (18, 6, 9, 2)
    assert row["p_value"] == pytest.approx(6 / 32, rel=1e-12)
    assert row["cost_diffs"] == pytest.approx(SIX_BY_THREE_COST)
    assert row["cost_instances"] == [f"robotouille/synchronous/t6/{i}" for i in SIX_BY_THREE_INSTANCES]
    assert paired_permutation_p(row["cost_diffs"], row["cost_instances"]) == 2 / 64
    c.close()


# -- the notes' words -------------------------------------------------------------------------------------


def test_interval_note_names_the_interval():
    one = {"episodes": 6, "instances": 6, "deff": 1.0}
    assert interval_note([one, one]) == "Intervals: Wilson 95% (one seed per instance)."
    assert interval_note([]) == ""
    # 6 instances x 3 seeds with deff 1.84: ICC = 0.84 / (3 - 1) = 0.42
    six = {"episodes": 18, "instances": 6, "deff": 1.84}
    assert interval_note([six]) == (
        "Intervals: Wilson 95%, widened by the design effect where an instance ran several seeds (6 instances x 3 seeds; "
        "ICC 0.42, deff 1.84): Wilson's interval at n / deff, deff = 1 + (m - 1) ICC (Kish) with the ICC by one-way "
        "ANOVA over the instances, truncated at 0 (deff 1: not widened)."
    )
    single = {"episodes": 3, "instances": 1, "deff": 1.0}
    assert interval_note([six, {"episodes": 10, "instances": 4, "deff": 1.0}, single, one]) == (
        "Intervals: Wilson 95%, widened by the design effect where an instance ran several seeds (3 of the 4 cells: "
        "1 instance x 3 seeds, 4 instances x 2.50 seeds (mean), 6 instances x 3 seeds; ICC 0.00 to 0.42, deff 1.00 to "
        "1.84; a single instance: no ICC estimate, deff 1): Wilson's interval at n / deff, deff = 1 + (m - 1) ICC "
        "(Kish) with the ICC by one-way ANOVA over the instances, truncated at 0 (deff 1: not widened). The other "
        "cells: plain Wilson 95% (one seed per instance)."
    )


def test_test_notes_name_the_test():
    assert mcnemar_note([(5, 5), (0, 0)]) == (
        "p: exact McNemar test (two-sided, binomial on the discordant pairs; one seed per instance)."
    )
    assert mcnemar_note([(18, 6)]).startswith(
        "p: clustered McNemar test, exact: the two arms swapped within each instance, all its seeds together"
    )
    assert mcnemar_note([]) == ""
    head = (
        "cost p: two-sided sign-flip permutation test over instances (each instance's paired differences summed over "
        "its seeds, the sign flipped per instance): "
    )
    six = clustered_permutation_test(SIX_BY_THREE_COST, SIX_BY_THREE_INSTANCES)
    assert permutation_note([six, None]) == head + "exact, all 2^6 patterns."
    three = clustered_permutation_test([1.0, 2.0, 3.0])
    sampled = sign_flip_test([1.0] * 21)
    zero = sign_flip_test([0.0])
    assert permutation_note([six, three, sampled, zero]) == head + (
        "1 test with no instance's difference non-zero, p = 1; exact, all 2^3 to 2^6 patterns (2 tests); 20,000 "
        "random sign patterns with numpy seed 20251, p = (hits + 1) / (patterns + 1), where more than 20 instances "
        "differ (1 test)."
    )
    assert permutation_note([]) == ""
