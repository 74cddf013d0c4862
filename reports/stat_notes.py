"""The words a table note uses for its intervals and tests, from the rows the table shows.

A reader must be able to tell from the note alone what an interval or a p-value is: a plain
Wilson interval or one widened by the design effect of repeated seeds (and by how much), an
exact McNemar test or its clustered form, a sign-flip test enumerated exactly or sampled. Each
function here reads that off the table's own rows, so the note cannot claim a method the
numbers did not use.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from reports.stats import EXACT_MAX, SAMPLES, SEED, SignFlipTest


def _num(x: float) -> str:
    return f"{x:.0f}" if float(x).is_integer() else f"{x:.2f}"


def _span(values: Sequence[float], fmt: str = "{:.2f}") -> str:
    lo, hi = min(values), max(values)
    return fmt.format(lo) if fmt.format(lo) == fmt.format(hi) else f"{fmt.format(lo)} to {fmt.format(hi)}"


def _seeds(episodes: float, instances: float) -> str:
    m = episodes / instances
    return f"{_num(m)} seeds" if float(m).is_integer() else f"{m:.2f} seeds (mean)"


def _design(k: int, seeds: str) -> str:
    return f"{k} instance{'' if k == 1 else 's'} x {seeds}"


def interval_note(cells: Iterable[Mapping[str, Any]]) -> str:
    """What the rate cells' 95% intervals are: "Wilson 95%" when every cell's instances ran one
    seed each; otherwise Wilson's interval at the effective sample size n / deff, with the design
    (k instances x n seeds), the intra-class correlation and the design effect of the cells that
    have several seeds per instance (a range over several cells; a cell of one instance has no
    ICC estimate and deff 1).

    ``cells`` need ``episodes``, ``instances`` and ``deff`` (the SQL's instance_deff). "" for no cells.
    """
    rows = [c for c in cells if c.get("episodes")]
    if not rows:
        return ""
    clustered = [c for c in rows if c.get("instances") and c["episodes"] > c["instances"]]
    if not clustered:
        return "Intervals: Wilson 95% (one seed per instance)."
    designs = sorted({(int(c["instances"]), _seeds(c["episodes"], c["instances"])) for c in clustered})
    if len(designs) <= 3:
        design = ", ".join(_design(k, n) for k, n in designs)
    else:
        ks = [k for k, _ in designs]
        design = f"{_span(ks, '{:.0f}')} instances x {_span([c['episodes'] / c['instances'] for c in clustered])} seeds"
    estimable = [c for c in clustered if c["instances"] >= 2]
    iccs, deffs = [], []
    for c in estimable:
        deff = float(c["deff"] if c.get("deff") is not None else 1.0)
        deffs.append(deff)
        iccs.append((deff - 1.0) / (c["episodes"] / c["instances"] - 1.0))
    measured = f"ICC {_span(iccs)}, deff {_span(deffs)}" if estimable else ""
    if len(estimable) < len(clustered):
        measured = _and(measured, "a single instance: no ICC estimate, deff 1")
    which = "" if len(clustered) == len(rows) else f"{len(clustered)} of the {len(rows)} cells: "
    rest = "" if len(clustered) == len(rows) else " The other cells: plain Wilson 95% (one seed per instance)."
    return (
        f"Intervals: Wilson 95%, widened by the design effect where an instance ran several seeds ({which}{design}; "
        f"{measured}): Wilson's interval at n / deff, deff = 1 + (m - 1) ICC (Kish) with the ICC by one-way ANOVA over "
        f"the instances, truncated at 0 (deff 1: not widened).{rest}"
    )


def _tests(n: int) -> str:
    return f"{n} test{'' if n == 1 else 's'}"


def _and(a: str, b: str) -> str:
    return f"{a}; {b}" if a else b


def rate_clustered(cells: Iterable[Mapping[str, Any]]) -> bool:
    """Whether any cell's instances ran several seeds each (its interval is widened)."""
    return any(c.get("instances") and c.get("episodes") and c["episodes"] > c["instances"] for c in cells)


def mcnemar_note(pairings: Iterable[tuple[int, int]]) -> str:
    """What the success p-values are, from each comparison's (paired units, paired instances):
    the exact McNemar (binomial) test when every instance ran one seed; otherwise the clustered
    McNemar test, exact, that swaps the arms of an instance with all its seeds together."""
    ps = [(p, k) for p, k in pairings if p]
    if not ps:
        return ""
    if all(p == k for p, k in ps):
        return "p: exact McNemar test (two-sided, binomial on the discordant pairs; one seed per instance)."
    return (
        "p: clustered McNemar test, exact: the two arms swapped within each instance, all its seeds together "
        "(the signs of each instance's only-A minus only-B count flipped; every sign pattern counted; Durkalski et al. "
        "2003's statistic), two-sided. It is the exact McNemar test where each instance ran one seed."
    )


def permutation_note(tests: Iterable[SignFlipTest | None], what: str = "cost p") -> str:
    """What the permutation p-values are: sign flips of whole instances (each instance's paired
    differences summed over its seeds), exact with 2^k patterns (k: instances with a non-zero
    total, the range over the table), or sampled (count and seed) above EXACT_MAX instances."""
    ts = [t for t in tests if t is not None]
    if not ts:
        return ""
    exact = [t for t in ts if t.exact]
    sampled = [t for t in ts if not t.exact]
    head = (
        f"{what}: two-sided sign-flip permutation test over instances (each instance's paired differences summed over "
        "its seeds, the sign flipped per instance)"
    )
    parts = []
    trivial = [t for t in exact if t.units == 0]
    exact = [t for t in exact if t.units > 0]
    if trivial:
        parts.append(
            f"{_tests(len(trivial))} with no instance's difference non-zero, p = 1"
            if exact or sampled
            else "no instance's difference is non-zero, p = 1"
        )
    if exact:
        ks = sorted({t.units for t in exact})
        span = f"2^{ks[0]}" if len(ks) == 1 else f"2^{ks[0]} to 2^{ks[-1]}"
        parts.append(f"exact, all {span} patterns" + ("" if not (sampled or trivial) else f" ({_tests(len(exact))})"))
    if sampled:
        seeds = sorted({t.seed for t in sampled if t.seed is not None})
        counts = sorted({t.patterns for t in sampled})
        parts.append(
            f"{', '.join(f'{c:,}' for c in counts)} random sign patterns with numpy seed "
            f"{', '.join(str(s) for s in seeds)}, p = (hits + 1) / (patterns + 1), where more than {EXACT_MAX} "
            f"instances differ" + ("" if not (exact or trivial) else f" ({_tests(len(sampled))})")
        )
    return f"{head}: {'; '.join(parts)}."


#: The rule, for notes that describe the test before any row exists (intros).
PERMUTATION_RULE = (
    f"sign-flip permutation over instances: exact up to {EXACT_MAX} instances with a non-zero difference, "
    f"else {SAMPLES:,} random patterns (seed {SEED})"
)
