"""Statistics the SQL cannot express compactly, and reference implementations of the SQL macros.

Success-rate intervals (Wilson, widened for repeated seeds of one instance) and the exact McNemar
test are SQL macros (``reports/sql/macros.sql``) so that ad-hoc queries get them too; the Python
versions here are what the tests check those macros against. For binary outcomes the exact paired
permutation test *is* the exact McNemar test, so :func:`paired_permutation_p` is used for
continuous paired quantities (dollars per episode between two arms on the same units).
:func:`holm` adjusts the p-values of a table that makes several comparisons.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from fractions import Fraction

import numpy as np

#: enumerate every sign pattern up to this many non-zero differences (2**16 patterns)
EXACT_MAX = 16
#: Monte Carlo sign patterns above EXACT_MAX (fixed seed: the same data gives the same p)
SAMPLES = 20_000
SEED = 20251


def paired_permutation_p(
    diffs: Sequence[float], *, exact_max: int = EXACT_MAX, samples: int = SAMPLES, seed: int = SEED
) -> float:
    """Two-sided p-value of H0 "mean paired difference is 0" by random sign flips.

    Under H0 each pair's difference is as likely to be +d as -d. The p-value is the share of
    sign patterns whose |sum| is at least the observed |sum|: exact (all 2**n patterns) when at
    most ``exact_max`` differences are non-zero, otherwise ``(hits + 1) / (samples + 1)`` over
    ``samples`` random patterns. Zero differences do not change the sum and are dropped.
    """
    d = np.asarray([x for x in diffs if x != 0 and not math.isnan(x)], dtype=np.float64)
    n = d.size
    if n == 0:
        return 1.0
    observed = abs(float(d.sum()))
    tol = 1e-9 * max(1.0, observed)
    if n <= exact_max:
        patterns = ((np.arange(2**n)[:, None] >> np.arange(n)[None, :]) & 1) * 2 - 1
        sums = np.abs(patterns @ d)
        return float(np.count_nonzero(sums >= observed - tol)) / float(2**n)
    # a random sign pattern = random bits; sum(s_i d_i) = 2 * sum(d_i where bit) - sum(d_i).
    # Work in blocks with one reused float buffer (allocating the whole matrix is much slower).
    rng = np.random.default_rng(seed)
    total = float(d.sum())
    block = 1000
    buf = np.empty((block, n), dtype=np.float64)
    hits = 0
    done = 0
    while done < samples:
        k = min(block, samples - done)
        bits = np.unpackbits(rng.integers(0, 256, size=(k, (n + 7) // 8), dtype=np.uint8), axis=1, count=n)
        np.copyto(buf[:k], bits)
        sums = np.abs(2.0 * (buf[:k] @ d) - total)
        hits += int(np.count_nonzero(sums >= observed - tol))
        done += k
    return (hits + 1) / (samples + 1)


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
