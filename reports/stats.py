"""Statistics the SQL cannot express compactly, and reference implementations of the SQL macros.

Success-rate intervals (Wilson, widened for repeated seeds of one instance) and the clustered
McNemar test are SQL macros (``reports/sql/macros.sql``) so that ad-hoc queries get them too; the
Python versions here are what the tests check those macros against.

Several seeds of one instance are not independent units, so every paired test here permutes
whole instances: under H0 the two arms are exchangeable *within an instance*, so the sign of
the instance's total paired difference (summed over its seeds) is flipped as one unit. The
intervals already respect the same clustering (the design effect). With one seed per instance
each instance is one pair and the tests are the ordinary ones: the paired sign-flip test, and
for binary outcomes the exact McNemar (binomial) test.

* :func:`sign_flip_test` / :func:`clustered_permutation_test`: the cost (continuous) test, exact
  over all 2**k sign patterns up to k = :data:`EXACT_MAX` instances, Monte Carlo above that.
* :func:`clustered_mcnemar_exact`: the success (binary) test, exact for any k (the totals are
  integers, so the permutation distribution is counted by convolution, not enumerated).
* :func:`holm` adjusts the p-values of a table that makes several comparisons.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Sequence
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

#: enumerate every sign pattern up to this many instances with a non-zero total (2**20 patterns)
EXACT_MAX = 20
#: Monte Carlo sign patterns above EXACT_MAX (fixed seed: the same data gives the same p)
SAMPLES = 20_000
SEED = 20251


@dataclass(frozen=True)
class SignFlipTest:
    """A sign-flip permutation test's p-value and how it was computed (for the table notes).

    ``units`` is the number of sign-flip units (instances) with a non-zero total; ``exact``
    says whether all ``patterns`` = 2**units sign patterns were enumerated, else ``patterns``
    random ones were drawn with ``seed`` and p = (hits + 1) / (patterns + 1).
    """

    p: float
    units: int
    exact: bool
    patterns: int
    seed: int | None = None


def cluster_totals(diffs: Sequence[float | None], clusters: Sequence[Hashable] | None = None) -> list[float]:
    """Sum the paired differences of each cluster (instance), in first-appearance order.

    ``clusters[i]`` is the instance of pair ``i``; ``None`` makes every pair its own cluster
    (one seed per instance). None or NaN differences (a pair without a cost) are left out.
    """
    if clusters is None:
        return [float(d) for d in diffs if d is not None and not math.isnan(d)]
    if len(clusters) != len(diffs):
        raise ValueError(f"{len(diffs)} differences but {len(clusters)} cluster keys")
    totals: dict[Hashable, float] = {}
    for d, c in zip(diffs, clusters):
        if d is not None and not math.isnan(d):
            totals[c] = totals.get(c, 0.0) + float(d)
    return list(totals.values())


def _half_sums(v: np.ndarray) -> np.ndarray:
    """sum(s_i v_i) for every sign pattern s of ``v`` (2**len(v) values)."""
    n = v.size
    patterns = ((np.arange(2**n)[:, None] >> np.arange(n)[None, :]) & 1) * 2 - 1
    return patterns @ v


def sign_flip_test(
    totals: Sequence[float], *, exact_max: int = EXACT_MAX, samples: int = SAMPLES, seed: int = SEED
) -> SignFlipTest:
    """Two-sided sign-flip permutation test of H0 "the mean of ``totals`` is 0".

    Under H0 each unit's total is as likely to be +t as -t (the two arms are exchangeable within
    the unit), and the p-value is the share of sign patterns whose |sum| is at least the
    observed |sum| (Fisher's randomisation test on matched units; at the level of the cluster,
    the unit of the design: Gail, Mark, Carroll, Green and Pee, "On design considerations and
    randomization-based inference for community intervention trials", Statistics in Medicine
    15, 1996). Zero totals do not change the sum and are dropped; k units remain.

    Exact when k <= ``exact_max``: the 2**k sums are split in two halves of 2**(k/2) sums each,
    and for each sum of one half the sums of the other that reach the observed |sum| are counted
    by binary search (2**20 patterns cost two arrays of 1024). Above that, ``samples`` random
    patterns from ``numpy.random.default_rng(seed)``, p = (hits + 1) / (samples + 1) (the
    observed pattern counts as one; Phipson and Smyth, "Permutation p-values should never be
    zero", Stat. Appl. Genet. Mol. Biol. 9, 2010).
    """
    d = np.asarray([x for x in totals if x != 0 and not math.isnan(x)], dtype=np.float64)
    k = d.size
    if k == 0:
        return SignFlipTest(1.0, 0, True, 1)
    observed = abs(float(d.sum()))
    threshold = observed - 1e-9 * max(1.0, observed)  # ties in exact arithmetic count
    if threshold <= 0:  # observed sum 0: every pattern reaches it
        return SignFlipTest(1.0, k, k <= exact_max, 2**k if k <= exact_max else samples, None if k <= exact_max else seed)
    if k <= exact_max:
        left = _half_sums(d[: k // 2])
        right = np.sort(_half_sums(d[k // 2 :]))
        # |a + b| >= t  <=>  b >= t - a  or  b <= -t - a (disjoint since t > 0)
        high = right.size - np.searchsorted(right, threshold - left, side="left")
        low = np.searchsorted(right, -threshold - left, side="right")
        hits = int(high.sum() + low.sum())
        return SignFlipTest(hits / float(2**k), k, True, 2**k)
    # a random sign pattern = random bits; sum(s_i d_i) = 2 * sum(d_i where bit) - sum(d_i).
    # Work in blocks with one reused float buffer (allocating the whole matrix is much slower).
    rng = np.random.default_rng(seed)
    total = float(d.sum())
    block = 1000
    buf = np.empty((block, k), dtype=np.float64)
    hits = 0
    done = 0
    while done < samples:
        m = min(block, samples - done)
        bits = np.unpackbits(rng.integers(0, 256, size=(m, (k + 7) // 8), dtype=np.uint8), axis=1, count=k)
        np.copyto(buf[:m], bits)
        sums = np.abs(2.0 * (buf[:m] @ d) - total)
        hits += int(np.count_nonzero(sums >= threshold))
        done += m
    return SignFlipTest((hits + 1) / (samples + 1), k, False, samples, seed)


def clustered_permutation_test(
    diffs: Sequence[float | None],
    clusters: Sequence[Hashable] | None = None,
    *,
    exact_max: int = EXACT_MAX,
    samples: int = SAMPLES,
    seed: int = SEED,
) -> SignFlipTest:
    """The paired permutation test of a mean difference (e.g. dollars per episode, arm A minus
    arm B on the same units), permuting whole instances: ``diffs`` are per pair (instance, seed),
    ``clusters`` their instances (:func:`cluster_totals`), and the sign of each instance's total
    is flipped together (:func:`sign_flip_test`). With one pair per instance (``clusters`` None or
    all distinct) it is the ordinary paired sign-flip test."""
    return sign_flip_test(cluster_totals(diffs, clusters), exact_max=exact_max, samples=samples, seed=seed)


def paired_permutation_p(
    diffs: Sequence[float | None],
    clusters: Sequence[Hashable] | None = None,
    *,
    exact_max: int = EXACT_MAX,
    samples: int = SAMPLES,
    seed: int = SEED,
) -> float:
    """The p-value of :func:`clustered_permutation_test` (every pair its own instance without ``clusters``)."""
    return clustered_permutation_test(diffs, clusters, exact_max=exact_max, samples=samples, seed=seed).p


def instance_discordance(
    a_success: Sequence[bool], b_success: Sequence[bool], clusters: Sequence[Hashable] | None = None
) -> list[int]:
    """b_i - c_i per instance: the instance's pairs only A solved minus those only B solved
    (``clusters[j]`` the instance of pair j; None: every pair its own instance)."""
    diffs = [int(bool(a)) - int(bool(b)) for a, b in zip(a_success, b_success, strict=True)]
    return [int(t) for t in cluster_totals([float(x) for x in diffs], clusters)]


def clustered_mcnemar_exact(discordance: Sequence[int]) -> Fraction:
    """Exact two-sided clustered McNemar p-value from each instance's b_i - c_i.

    The permutation test that swaps the two arms within each instance (all its seeds together):
    under H0 each instance's D_i = b_i - c_i is as likely to be -D_i, and p = P[|sum s_i D_i| >=
    |sum D_i|] over the 2**k equally likely sign patterns s of the k instances with D_i != 0.
    Its statistic standardised by its permutation variance, (sum D_i)^2 / sum D_i^2, is the
    clustered McNemar statistic of Durkalski, Palesch, Lipsitz and Rust ("Analysis of clustered
    matched-pair data", Statistics in Medicine 22, 2003), which refers it to chi-square(1); this
    is the exact version of that test (also the cluster-level McNemar of Obuchowski, "On the
    comparison of correlated proportions for clustered data", Statistics in Medicine 17, 1998,
    with the variance taken under H0). The D_i are integers, so the distribution is counted by
    convolution, exactly, for any k (no enumeration, no sampling).

    With one pair per instance the D_i are +-1 and this is exactly the exact McNemar test
    (:func:`mcnemar_exact`): X ~ Bin(b + c, 1/2), p = min(1, 2 P[X <= min(b, c)]).
    Mirrors the SQL macro ``clustered_mcnemar_p``.
    """
    ds = [abs(int(x)) for x in discordance if int(x) != 0]
    k = len(ds)
    if k == 0:
        return Fraction(1)
    half = sum(ds)
    counts = np.zeros(2 * half + 1, dtype=object)  # Python ints: exact for any k
    counts[:] = 0
    counts[0] = 1  # index j <-> partial sum j - (the |D| processed so far); grows by 2|D| each step
    width = 1
    for d in ds:
        nxt = np.zeros(width + 2 * d, dtype=object)
        nxt[:] = 0
        nxt[:width] += counts[:width]  # s_i = -1
        nxt[2 * d :] += counts[:width]  # s_i = +1
        counts[: width + 2 * d] = nxt
        width += 2 * d
    observed = abs(sum(int(x) for x in discordance))
    sums = np.arange(width) - half
    hits = int(sum(counts[np.abs(sums) >= observed]))
    return Fraction(hits, 2**k)


# -- reference implementations (used by tests to check the SQL macros) ---------------------------

Z95 = 1.959963984540054


def wilson(k: float, n: float, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval for k successes in n trials, clamped to [0, 1].

    The bounds lie in [0, 1] in exact arithmetic, and are exactly 0 for k = 0 and 1 for k = n;
    rounding can miss both by ~1e-17 either way, hence the clamp and the two exact ends. ``k``
    and ``n`` may be fractional (an effective sample size, :func:`cluster_wilson`).
    """
    if n <= 0:
        raise ValueError("wilson interval needs n > 0")
    p = k / n
    centre = p + z * z / (2 * n)
    half = z * math.sqrt(max(p * (1 - p), 0.0) / n + z * z / (4 * n * n))
    den = 1 + z * z / n
    lo = 0.0 if k <= 0 else max(0.0, (centre - half) / den)
    hi = 1.0 if k >= n else min(1.0, (centre + half) / den)
    return lo, hi


def design_effect(clusters: Sequence[tuple[int, int]]) -> float:
    """Kish's design effect of a success rate whose episodes come in clusters (one per instance).

    ``clusters`` holds ``(successes, episodes)`` per instance (several seeds of one instance form
    a cluster). deff = 1 + (m - 1) * rho (Kish, *Survey Sampling*, Wiley 1965, sec. 5.4), with m
    the mean cluster size N / G and rho the one-way ANOVA estimator of the intra-class
    correlation (Donner, "A review of inference procedures for the intraclass correlation
    coefficient in the one-way random effects model", Int. Stat. Review 54, 1986):

        MSB = sum m_i (p_i - p)^2 / (G - 1)        (between instances)
        MSW = sum m_i p_i (1 - p_i) / (N - G)      (between seeds of one instance)
        m0  = (N - sum m_i^2 / N) / (G - 1)
        rho = (MSB - MSW) / (MSB + (m0 - 1) MSW), truncated at 0

    rho is taken as 0 (deff = 1, the plain Wilson interval) when it cannot be estimated: fewer
    than two instances, no instance with two episodes (N = G), or no variation at all (every
    episode succeeded or every one failed). Truncating at 0 means repeated seeds never *narrow*
    an interval.
    """
    sizes = [m for _, m in clusters if m > 0]
    g = len(sizes)
    n = sum(sizes)
    if g < 2 or n == g:
        return 1.0
    k = sum(y for y, m in clusters if m > 0)
    p = k / n
    msb = sum(y * y / m for y, m in clusters if m > 0) - n * p * p  # = sum m_i (p_i - p)^2
    msb /= g - 1
    msw = (k - sum(y * y / m for y, m in clusters if m > 0)) / (n - g)  # = sum m_i p_i (1 - p_i) / (N - G)
    m0 = (n - sum(m * m for m in sizes) / n) / (g - 1)
    den = msb + (m0 - 1) * msw
    if den <= 0:
        return 1.0
    rho = max(0.0, (msb - msw) / den)
    return 1.0 + (n / g - 1) * rho


def cluster_wilson(clusters: Sequence[tuple[int, int]], z: float = Z95) -> tuple[float, float]:
    """Wilson interval of the pooled success rate with the effective sample size N / deff.

    The rate stays k / N; the interval is Wilson's at n_eff = N / deff (:func:`design_effect`),
    the effective-sample-size Wilson interval for clustered binary data (Korn and Graubard,
    "Confidence intervals for proportions with small expected number of positive counts
    estimated from survey data", Survey Methodology 24, 1998; compared in Dean and Pagano,
    J. Survey Statistics and Methodology 3, 2015). One episode per instance gives exactly the
    plain Wilson interval. Mirrors the SQL macros ``cluster_wilson_low/high``.
    """
    n = sum(m for _, m in clusters)
    if n <= 0:
        raise ValueError("wilson interval needs n > 0")
    k = sum(y for y, _ in clusters)
    n_eff = n / design_effect(clusters)
    return wilson(k / n * n_eff, n_eff, z)


def holm(pvalues: Sequence[float | None]) -> list[float | None]:
    """Holm's step-down adjustment of the p-values of one table (Holm, "A simple sequentially
    rejective multiple test procedure", Scand. J. Statistics 6, 1979).

    With the m present p-values sorted p(1) <= ... <= p(m), the adjusted value of p(i) is
    max over j <= i of min(1, (m - j + 1) p(j)); rejecting where it is <= alpha controls the
    family-wise error rate at alpha. ``None`` (no test) stays ``None`` and does not count in m.
    Results are in the input order.
    """
    present = sorted((p, i) for i, p in enumerate(pvalues) if p is not None and not math.isnan(p))
    m = len(present)
    out: list[float | None] = [None] * len(pvalues)
    running = 0.0
    for rank, (p, i) in enumerate(present):
        running = max(running, min(1.0, (m - rank) * p))
        out[i] = running
    return out


def comparisons(pvalues: Sequence[float | None]) -> int:
    """How many tests a column of p-values holds (the m of :func:`holm`)."""
    return sum(1 for p in pvalues if p is not None and not math.isnan(p))


def mcnemar_exact(b: int, c: int) -> Fraction:
    """Exact two-sided McNemar p-value as a fraction: min(1, 2 P[X <= min(b, c)]), X ~ Bin(b+c, 1/2)."""
    n = b + c
    tail = sum(math.comb(n, k) for k in range(min(b, c) + 1))
    return min(Fraction(1), Fraction(2 * tail, 2**n))
