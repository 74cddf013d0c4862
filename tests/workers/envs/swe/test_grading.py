"""The official harness's grading (swebench) beside ours: the same verdict and the same per-test
statuses on every fixture case, a SWE-bench repository's log read by its own parser, the
``evaluations`` row of a judged submission."""

from __future__ import annotations

import json

import pytest

from schemas.records import EvaluationRecord
from tests.workers.envs.swe.sandbox_log import SandboxLog
from workers.envs.swe.evaluate import Evaluation, evaluate, evaluation_record, ours_resolved, parse_summary
from workers.envs.swe.examples import Fixtures
from workers.envs.swe.grading import OfficialGrade, check_grading, official_grade, parser_name
from workers.envs.swe.instances import SweInstance, load_instances
from workers.sandbox.base import SandboxSpec

pytest.importorskip("swebench.harness.grading", reason="the official grading needs the swebench package (extra swe)")


def _instance(fixtures: Fixtures, name: str) -> SweInstance:
    return next(i for i in load_instances(fixtures.tasks_file) if i.instance_id == f"fixture__{name}-1")


def _evaluate(inst: SweInstance, patch: str, log: SandboxLog, grading: str = "both") -> Evaluation:
    return evaluate(inst, patch, lambda: log(SandboxSpec(inst.repo_path, inst.base_commit)), grading=grading)  # type: ignore[arg-type]


def _both(ev: Evaluation) -> tuple[bool, str, bool, str | None]:
    assert ev.official is not None
    assert dict(ev.official.tests) == dict(ev.tests)  # test by test, the same statuses
    return ev.resolved, ev.reason, ev.official.resolved, ev.official.status


def test_gold_patches_resolve_all_six_by_both_gradings(fixtures: Fixtures, sandboxes: SandboxLog) -> None:
    results = {i.instance_id: _evaluate(i, i.patch, sandboxes) for i in load_instances(fixtures.tasks_file)}
    assert {k: _both(e) for k, e in results.items()} == {
        f"fixture__{n}-1": (True, "resolved", True, "RESOLVED_FULL")
        for n in ("offbyone", "format", "twofiles", "newfunc", "hang", "p2p")
    }
    assert {e.official.parser for e in results.values() if e.official} == {"parse_log_pytest"}
    assert all((e.success, e.graded_by, e.verdict_reason) == (True, "official", "resolved") for e in results.values())
    assert dict(results["fixture__twofiles-1"].official.tests) == {  # type: ignore[union-attr]
        "tests/test_convert.py::test_inches_to_cm": "PASSED",
        "tests/test_convert.py::test_cm_to_inches": "PASSED",
        "tests/test_convert.py::test_zero": "PASSED",
    }


def test_empty_patch_is_not_resolved_by_either(fixtures: Fixtures, sandboxes: SandboxLog) -> None:
    ev = _evaluate(_instance(fixtures, "offbyone"), "", sandboxes)
    assert _both(ev) == (False, "no_patch", False, None)
    assert set(ev.tests.values()) == {"MISSING"}
    assert sandboxes.opened == []


def test_patch_that_does_not_apply_is_not_resolved_by_either(fixtures: Fixtures, sandboxes: SandboxLog) -> None:
    ev = _evaluate(_instance(fixtures, "offbyone"), _instance(fixtures, "format").patch, sandboxes)
    assert _both(ev) == (False, "patch_failed", False, None)
    assert set(ev.tests.values()) == {"MISSING"}


def test_wrong_patches_fail_by_both_gradings_test_by_test(fixtures: Fixtures, sandboxes: SandboxLog) -> None:
    got = {name: _evaluate(_instance(fixtures, name), patch, sandboxes) for name, patch in fixtures.wrong_patches.items()}
    assert {name: _both(ev) for name, ev in got.items()} == {
        "format": (False, "tests_failed", False, "RESOLVED_NO"),
        "p2p": (False, "tests_failed", False, "RESOLVED_NO"),
        "hang": (False, "timeout", False, None),  # the harness writes no report for a run past its timeout
    }
    assert dict(got["p2p"].tests) == {
        "tests/test_flags.py::test_variants": "PASSED",
        "tests/test_flags.py::test_false": "FAILED",
        "tests/test_flags.py::test_empty": "PASSED",
    }
    p2p = got["p2p"].official
    assert p2p is not None
    assert (p2p.fail_to_pass_success, p2p.fail_to_pass_failure) == (("tests/test_flags.py::test_variants",), ())
    assert (p2p.pass_to_pass_success, p2p.pass_to_pass_failure) == (
        ("tests/test_flags.py::test_empty",),
        ("tests/test_flags.py::test_false",),
    )
    assert got["p2p"].failing_tests() == ["tests/test_flags.py::test_false"]
    assert set(got["hang"].tests.values()) == {"MISSING"}


def test_grading_ours_runs_no_official_grade(fixtures: Fixtures, sandboxes: SandboxLog) -> None:
    ev = _evaluate(_instance(fixtures, "format"), fixtures.wrong_patches["format"], sandboxes, grading="ours")
    assert (ev.official, ev.graded_by, ev.success, ev.verdict_reason) == (None, "ours", False, "tests_failed")


def _synthetic(repo: str, f2p: tuple[str, ...], p2p: tuple[str, ...]) -> SweInstance:
    return SweInstance("x__y-1", repo, "0" * 40, "issue", f2p, p2p, "", "", "/nonexistent")


DJANGO_LOG = """Testing against Django installed in '/testbed/django'
Importing application admin_views
Creating test database for alias 'default'...
System check identified no issues (0 silenced).
test_add_view (admin_views.tests.AdminViewBasicTest) ... ok
test_change_view (admin_views.tests.AdminViewBasicTest) ... FAIL
test_delete_view (admin_views.tests.AdminViewBasicTest) ... skipped 'no database'
test_history_view (admin_views.tests.AdminViewBasicTest) ... ERROR

======================================================================
FAIL: test_change_view (admin_views.tests.AdminViewBasicTest)
----------------------------------------------------------------------
Traceback (most recent call last):
AssertionError: 302 != 200

----------------------------------------------------------------------
Ran 4 tests in 0.112s

FAILED (failures=1, errors=1, skipped=1)
"""


def test_a_django_log_goes_through_djangos_parser() -> None:
    add, change = (
        "test_add_view (admin_views.tests.AdminViewBasicTest)",
        "test_change_view (admin_views.tests.AdminViewBasicTest)",
    )
    delete, history = (
        "test_delete_view (admin_views.tests.AdminViewBasicTest)",
        "test_history_view (admin_views.tests.AdminViewBasicTest)",
    )
    inst = _synthetic("django/django", (add, change), (delete,))
    grade = official_grade(inst, DJANGO_LOG, patch_applied=True, exit_code=1)
    assert grade == OfficialGrade(
        resolved=False,
        status="RESOLVED_PARTIAL",  # one of two FAIL_TO_PASS passes; the skipped PASS_TO_PASS test is no failure
        parser="parse_log_django",
        tests={add: "PASSED", change: "FAILED", delete: "SKIPPED"},
        fail_to_pass_success=(add,),
        fail_to_pass_failure=(change,),
        pass_to_pass_success=(),  # 4.x lists a skipped test as neither success nor failure
        pass_to_pass_failure=(),
    )
    fixed = DJANGO_LOG.replace(f"{change} ... FAIL", f"{change} ... ok")
    assert official_grade(inst, fixed, patch_applied=True, exit_code=1).status == "RESOLVED_FULL"
    # read as pytest's log (a repository SWE-bench does not know), the runner's lines are no tests
    as_pytest = official_grade(_synthetic("fixture/admin", (add,), ()), DJANGO_LOG, patch_applied=True, exit_code=1)
    assert (as_pytest.parser, as_pytest.status, dict(as_pytest.tests)) == ("parse_log_pytest", "RESOLVED_NO", {add: "MISSING"})
    inst_h = _synthetic("django/django", (history,), ())
    assert official_grade(inst_h, DJANGO_LOG, patch_applied=True).tests == {history: "ERROR"}


def test_parser_names_of_swebench_repositories() -> None:
    assert [parser_name(r) for r in ("django/django", "sympy/sympy", "astropy/astropy", "psf/requests", "me/mine")] == [
        "parse_log_django",
        "parse_log_sympy",
        "parse_log_pytest_v2",  # 4.x names astropy's parser by its function
        "parse_log_pytest_options",  # and psf/requests' likewise
        "parse_log_pytest",
    ]


PYTEST_LOG = """============================= test session starts ==============================
collected 3 items

tests/test_a.py .s.                                                      [100%]

=========================== short test summary info ============================
PASSED tests/test_a.py::test_fix
SKIPPED [1] tests/test_a.py:9: needs a network
SKIPPED tests/test_a.py::test_kept
PASSED tests/test_a.py::test_other
========================= 2 passed, 1 skipped in 0.02s =========================
"""


@pytest.mark.parametrize(
    ("f2p", "p2p", "resolved", "official", "status"),
    [
        (
            ("tests/test_a.py::test_fix",),
            ("tests/test_a.py::test_kept", "tests/test_a.py::test_other"),
            True,
            True,
            "RESOLVED_FULL",
        ),
        # swebench 4.x (the pinned harness) counts a skipped FAIL_TO_PASS test as neither passed nor
        # failed, and with no failure reports FULL; our criterion does not resolve it. The two
        # verdicts differ here, and the evaluations row keeps both (ours_resolved, official_resolved)
        (("tests/test_a.py::test_kept",), ("tests/test_a.py::test_other",), False, True, "RESOLVED_FULL"),
        (("tests/test_a.py::test_fix", "tests/test_a.py::test_gone"), (), False, False, "RESOLVED_PARTIAL"),
    ],
)
def test_skipped_and_missing_tests_in_both_gradings(f2p, p2p, resolved, official, status) -> None:
    """A skipped PASS_TO_PASS test is kept and a missing test fails in both; a skipped
    FAIL_TO_PASS test is the one known difference (above)."""
    inst = _synthetic("fixture/a", f2p, p2p)
    grade = official_grade(inst, PYTEST_LOG, patch_applied=True, exit_code=0)
    ours = {t: parse_summary(PYTEST_LOG, (*f2p, *p2p)).get(t, "MISSING") for t in (*f2p, *p2p)}
    assert (ours_resolved(inst, ours), grade.resolved, grade.status) == (resolved, official, status)
    assert dict(grade.tests) == ours


def test_the_pinned_harness_reads_the_log_not_the_exit_status() -> None:
    """swebench 4.x grades the log alone: a test command that exited non-zero with only PASSED
    lines still counts (5.x added a cross-check with the exit status)."""
    inst = _synthetic("fixture/a", ("tests/test_a.py::test_fix",), ())
    assert official_grade(inst, PYTEST_LOG, patch_applied=True, exit_code=0).resolved is True
    forged = official_grade(inst, PYTEST_LOG, patch_applied=True, exit_code=1)
    assert (forged.resolved, forged.status) == (True, "RESOLVED_FULL")


def test_check_grading() -> None:
    assert [check_grading(g) for g in ("ours", "official", "both")] == ["ours", "official", "both"]
    with pytest.raises(ValueError) as err:
        check_grading("harness")
    assert str(err.value) == "grading must be one of ours, official, both, got 'harness'"


def test_the_evaluation_row_of_a_judged_submission(fixtures: Fixtures, sandboxes: SandboxLog) -> None:
    inst = _instance(fixtures, "p2p")
    patch = fixtures.wrong_patches["p2p"]
    ev = _evaluate(inst, patch, sandboxes)
    row = evaluation_record("u1-1", inst, ev, patch)
    assert isinstance(row, EvaluationRecord)
    assert (
        row.episode_id,
        row.instance_id,
        row.resolved,
        row.reason,
        row.graded_by,
        row.grading,
        row.ours_resolved,
        row.official_resolved,
        row.official_status,
        row.official_parser,
        json.loads(row.tests),
        (row.fail_to_pass_passed, row.fail_to_pass_total, row.pass_to_pass_passed, row.pass_to_pass_total),
        row.patch,
        row.patch_bytes,
        row.log_bytes == len(row.log.encode("utf-8")),
    ) == (
        "u1-1",
        "swe/fixture__p2p-1",
        False,
        "tests_failed",
        "official",
        "both",
        False,
        False,
        "RESOLVED_NO",
        "parse_log_pytest",
        {
            "tests/test_flags.py::test_variants": "PASSED",
            "tests/test_flags.py::test_false": "FAILED",
            "tests/test_flags.py::test_empty": "PASSED",
        },
        (1, 1, 1, 2),
        patch,
        len(patch.encode("utf-8")),
        True,
    )
    assert "FAILED tests/test_flags.py::test_false" in row.log and row.duration_s > 0


def test_a_long_log_keeps_its_tail_and_says_its_size(fixtures: Fixtures) -> None:
    from schemas.records import EVALUATION_LOG_CAP
    from workers.envs.swe.evaluate import _logged

    inst = _instance(fixtures, "format")
    ev = _logged(Evaluation(False, "tests_failed"), ["é" * 150_000, "the summary"])
    assert ev.log_bytes == 300_012 and len(ev.log.encode("utf-8")) <= EVALUATION_LOG_CAP + 40
    assert ev.log.startswith("[log cut: the last part follows]\n") and ev.log.endswith("é\nthe summary")
    row = evaluation_record("e", inst, ev, "")
    assert (row.log_bytes, row.log) == (300_012, ev.log)


def test_the_environment_hands_each_evaluation_over_once(swe_env) -> None:
    env = swe_env("format")
    env.reset()
    first = env.call_tool("submit", {})
    assert env.take_records("e1", "r1") == []  # a review is not a judgement
    last = env.call_tool("submit", {})
    assert (first.done, last.done, last.success, last.info["eval_reason"], last.info["official_status"]) == (
        False,
        True,
        False,
        "no_patch",
        None,
    )
    rows = env.take_records("e1", "r1")
    assert [(r.episode_id, r.instance_id, r.reason, r.official_resolved, r.patch_bytes) for r in rows] == [
        ("e1", "swe/fixture__format-1", "no_patch", False, 0)
    ]
    assert env.take_records("e1", "r1") == []


def test_grading_official_is_refused_without_the_package(fixtures: Fixtures, sandboxes: SandboxLog, monkeypatch) -> None:
    from workers.envs import swe
    from workers.envs.registry import make_env

    monkeypatch.setattr(swe.grading, "official_problem", lambda: "no swebench here")
    with pytest.raises(ValueError) as err:
        make_env("swe/fixture__format-1", instances_file=str(fixtures.tasks_file), open_sandbox=sandboxes, grading="official")
    assert str(err.value) == "grading 'official': no swebench here"
    with pytest.raises(ValueError) as err:
        make_env("swe/fixture__format-1", instances_file=str(fixtures.tasks_file), open_sandbox=sandboxes, grading="both ")
    assert str(err.value) == "grading must be one of ours, official, both, got 'both '"
    assert sandboxes.opened == []
