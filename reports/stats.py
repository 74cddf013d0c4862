"""Statistics the SQL cannot express compactly: the paired permutation test of a mean difference.

Success-rate intervals (Wilson) and the exact McNemar test are SQL macros
(``reports/sql/macros.sql``) so that ad-hoc queries get them too. For binary outcomes the exact
paired permutation test *is* the exact McNemar test, so this module is used for continuous paired
quantities (dollars per episode between two arms on the same units).
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


def paired_permutation_p(diffs: Sequence[float], *, exact_max: int = EXACT_MAX, samples: int = SAMPLES, seed: int = SEED) -> float:
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


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval for k successes in n trials."""
    if n == 0:
        raise ValueError("wilson interval needs n > 0")
    p = k / n
    centre = p + z * z / (2 * n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    den = 1 + z * z / n
    return (centre - half) / den, (centre + half) / den


def mcnemar_exact(b: int, c: int) -> Fraction:
    """Exact two-sided McNemar p-value as a fraction: min(1, 2 P[X <= min(b, c)]), X ~ Bin(b+c, 1/2)."""
    n = b + c
    tail = sum(math.comb(n, k) for k in range(min(b, c) + 1))
    return min(Fraction(1), Fraction(2 * tail, 2**n))
