"""The sink actor killed mid-run, asserted like the other chaos scenarios: nothing lost,
nothing duplicated, no finished unit run or paid again (slow: ``pytest -m slow tests/pipeline/chaos``)."""

from __future__ import annotations

import pytest

from tests.pipeline.chaos import kills
from tests.pipeline.chaos.harness import ScenarioResult

pytestmark = pytest.mark.slow


def _assert_clean(res: ScenarioResult, runs: int) -> None:
    assert [str(c) for c in res.failures] == []
    assert (res.runs, res.passed) == (runs, runs)
    assert (res.lost, res.duplicated, res.overspend_usd) == (0, 0, 0.0)


def test_sink_sigkill_mid_run_restarts_then_resume_loses_and_repays_nothing(lab):
    _assert_clean(kills.sink_kill(lab, runs=2, units=12, restarts=True), 2)


def test_sink_gone_for_good_stops_the_driver_then_resume_reruns_only_what_was_never_written(lab):
    _assert_clean(kills.sink_kill(lab, runs=1, units=12, restarts=False), 1)
