"""Run folders with known rows (tests/doubles/known_run.py), written once per test session, and
one run folder the pipeline itself wrote (tests/reports/pipeline_run.py)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest

from tests.doubles.known_run import write_run_a, write_run_b
from tests.reports.pipeline_run import run_sweep


@pytest.fixture(scope="session")
def run_a(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_run_a(tmp_path_factory.mktemp("runs") / "runA")


@pytest.fixture(scope="session")
def run_b(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_run_b(tmp_path_factory.mktemp("runs") / "runB")


@pytest.fixture(scope="session")
def pipeline_run(ray_address: str, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, int, dict[str, Any]]:
    """``recap run`` of a small sweep on the session's local Ray (test double, a binding cap, a killed
    worker): (run folder, exit status, the killed unit)."""
    return run_sweep(tmp_path_factory.mktemp("pipeline"))


def same(actual: Any, expected: Any) -> bool:
    """Exact equality, except floats compared to 1e-12 relative (sums of binary fractions)."""
    if isinstance(expected, float) or isinstance(actual, float):
        if actual is None or expected is None:
            return actual is expected
        return math.isclose(actual, expected, rel_tol=1e-12, abs_tol=1e-15)
    if isinstance(expected, (list, tuple)) and isinstance(actual, (list, tuple)):
        return len(actual) == len(expected) and all(same(a, e) for a, e in zip(actual, expected))
    if isinstance(expected, dict) and isinstance(actual, dict):
        return actual.keys() == expected.keys() and all(same(actual[k], expected[k]) for k in expected)
    return actual == expected


def assert_rows(actual: list[dict[str, Any]], expected: list[dict[str, Any]]) -> None:
    """Every expected row, in order, with exactly the given columns' values."""
    assert len(actual) == len(expected), f"{len(actual)} rows, expected {len(expected)}:\n{actual}"
    for i, (a, e) in enumerate(zip(actual, expected)):
        sub = {k: a[k] for k in e}
        assert same(sub, e), f"row {i}:\n  got      {sub}\n  expected {e}"
