"""The chaos scenarios of ``tests/pipeline/chaos/lab.py``, asserted: nothing lost, nothing duplicated, no
money past a cap or paid twice, every check of every run passed.

Slow (minutes): ``pytest -m slow tests/pipeline/chaos`` or ``bash scripts/test.sh slow``.
"""

from __future__ import annotations

import pytest

from tests.pipeline.chaos import exposure, faults, folders, kills, signals
from tests.pipeline.chaos.harness import ScenarioResult

pytestmark = pytest.mark.slow


def assert_clean(res: ScenarioResult, runs: int, overspend: bool) -> None:
    assert [str(c) for c in res.failures] == []
    assert (res.runs, res.passed) == (runs, runs)
    assert (res.lost, res.duplicated) == (0, 0)
    assert res.overspend_usd == (0.0 if overspend else None)


def test_worker_sigkill_in_20_episodes_loses_and_duplicates_nothing(lab):
    res = kills.worker_kill(lab, runs=1, units=20)
    assert_clean(res, 1, overspend=False)
    names = [c.name for c in res.checks]
    assert "every returned episode has its terminal row" in names and "kills landed" in names


def test_gateway_and_budget_actors_killed_restart_restore_spend_and_keep_the_cap(lab):
    res = kills.gateway_kill(lab, runs=1)
    assert_clean(res, 1, overspend=True)


def test_driver_sigkill_then_resume_equals_an_uninterrupted_run_and_pays_completed_units_once(lab):
    res = kills.driver_kill(lab, runs=2)
    assert_clean(res, 2, overspend=True)


def test_transient_faults_and_context_length_are_handled_by_class_bounded_and_visible(lab):
    res = faults.provider_faults(lab)
    assert_clean(res, 2, overspend=False)


def test_429_storm_of_30_seconds(lab):
    res = faults.rate_limit_storm(lab, storm_s=30.0)
    assert_clean(res, 2, overspend=False)


def test_corrupt_parts_are_reported_and_resume_reruns_only_lost_units(lab):
    res = folders.corrupt_parts(lab)
    assert_clean(res, 1, overspend=False)


def test_no_key_in_files_logs_or_output_and_every_socket_on_loopback(lab):
    res = exposure.secrets_and_sockets(lab)
    assert_clean(res, 1, overspend=False)


def test_ctrl_c_once_lets_the_episodes_in_flight_finish_exits_130_and_the_resume_pays_nothing_twice(lab):
    res = signals.sigint(lab, presses=1)
    assert_clean(res, 1, overspend=True)
    assert "no call paid twice" in [c.name for c in res.checks]


def test_ctrl_c_twice_cuts_the_episodes_in_flight_and_keeps_every_paid_call(lab):
    res = signals.sigint(lab, presses=2)
    assert_clean(res, 1, overspend=True)
    assert "the second Ctrl-C cuts them" in [c.name for c in res.checks]


def test_a_sigkilled_drivers_ray_processes_are_stopped_by_its_watcher_or_else_by_the_resume_which_says_so(lab):
    res = signals.orphans(lab)
    assert_clean(res, 1, overspend=True)
    assert "no process of any of the three clusters is left" in [c.name for c in res.checks]


def test_unreadable_200_cap_attacks_never_overspend_across_sessions(lab):
    from tests.pipeline.chaos.guards import unreadable_attacks
    from workers.llm.offline.fake_server import UNREADABLE_MODES

    res = unreadable_attacks(lab)
    n = len(UNREADABLE_MODES) + 1
    assert_clean(res, n, overspend=True)
    assert res.name == f"unreadable-200 cap attacks ({n} tried, max overspend $0.000000)"
