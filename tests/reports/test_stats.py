"""reports/stats.py and the SQL macros it mirrors: Holm's adjustment, the clamped Wilson interval
and the instance-clustered Wilson interval, each against hand-computed values and an independent
computation (the step-down procedure itself; ANOVA from the raw 0/1 data; the score test solved
by bisection)."""

from __future__ import annotations

import math
import random

import duckdb
import numpy as np
import pytest

from reports.stats import Z95, cluster_wilson, comparisons, design_effect, holm, wilson
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
