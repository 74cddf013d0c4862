"""Our pytest reader (a user's ``benchmark: swe`` tasks) reads pytest's output whatever its options,
and a SWE-bench repository's log is read by the harness's own parser for it."""

from __future__ import annotations

import pytest

from workers.envs.swe.evaluate import parse_summary, read_tests
from workers.envs.swe.grading import harness_log, official_grade
from workers.envs.swe.instances import SweInstance
from workers.envs.swe.test_log import harness_test_section, read_pytest_log, strip_ansi

G, R, Y, B, X = "\x1b[32m", "\x1b[31m", "\x1b[33m", "\x1b[1m", "\x1b[0m"


def test_coloured_output() -> None:
    """``--color=yes`` wraps statuses (and the percentage) in ANSI escapes."""
    out = "\n".join(
        [
            f"t.py::test_a {G}PASSED{X}{G}                                   [ 50%]{X}",
            f"t.py::test_b {R}FAILED{X}{R}                                   [100%]{X}",
            f"{R}{B}={X} short test summary info {R}{B}={X}",
            f"{G}PASSED{X} t.py::test_a",
            f"{R}FAILED{X} t.py::test_b - {B}AssertionError{X}: assert 1 == 2",
        ]
    )
    assert strip_ansi(f"{G}PASSED{X}") == "PASSED"
    assert parse_summary(out) == {"t.py::test_a": "PASSED", "t.py::test_b": "FAILED"}
    assert parse_summary(f"{Y}t.py::test_c SKIPPED (no db){X}{Y} [100%]{X}") == {"t.py::test_c": "SKIPPED"}


def test_verbose_output() -> None:
    """``-v`` gives ``id STATUS [ NN%]``, a reason in parentheses for a skip or an xfail, and xdist
    prefixes its worker and progress; no ``-rA`` summary follows."""
    out = "\n".join(
        [
            "============================= test session starts ==============================",
            "collecting ... collected 5 items",
            "",
            "tests/test_x.py::test_a PASSED                                          [ 20%]",
            "tests/test_x.py::test_b FAILED                                          [ 40%]",
            "tests/test_x.py::test_c SKIPPED (needs a network)                       [ 60%]",
            "tests/test_x.py::test_d XFAIL (known bug)                               [ 80%]",
            "tests/test_x.py::Test::test_e ERROR                                     [100%]",
            "[gw1] [ 50%] PASSED tests/test_y.py::test_f",
            "E       assert FAILED",
            "========================= 1 failed, 2 passed in 0.10s ==========================",
        ]
    )
    assert parse_summary(out) == {
        "tests/test_x.py::test_a": "PASSED",
        "tests/test_x.py::test_b": "FAILED",
        "tests/test_x.py::test_c": "SKIPPED",
        "tests/test_x.py::test_d": "XFAIL",
        "tests/test_x.py::Test::test_e": "ERROR",
        "tests/test_y.py::test_f": "PASSED",
    }


def test_rA_summary() -> None:
    """The ``-rA`` summary: a skip given by its location (``SKIPPED [1] file:line: why``) names no
    test; a failure's message follows `` - `` (and may hold `` - `` itself); the summary, last,
    decides over the verbose line before it (a test whose teardown failed: PASSED then ERROR)."""
    out = "\n".join(
        [
            "t.py::test_a PASSED                                                      [ 50%]",
            "t.py::test_a ERROR                                                       [ 50%]",
            "=========================== short test summary info ============================",
            "PASSED t.py::test_a",
            "PASSED t.py::test_z",
            "SKIPPED [1] t.py:3: no network",
            "XFAIL t.py::test_d - reason: known - bug",
            "XPASS t.py::test_e",
            "ERROR t.py::test_a - RuntimeError: teardown",
            "FAILED t.py::test_b - AssertionError: x - y",
        ]
    )
    assert parse_summary(out) == {
        "t.py::test_a": "ERROR",
        "t.py::test_z": "PASSED",
        "t.py::test_d": "XFAIL",
        "t.py::test_e": "XPASS",
        "t.py::test_b": "FAILED",
    }


def test_old_pytest_lines() -> None:
    """Old pytest (the 3.x-4.x some SWE-bench repositories pin) prints ``id STATUS`` with no
    percentage in verbose mode."""
    out = "tests/test_x.py::test_a PASSED\ntests/test_x.py::test_b FAILED\ntests/test_x.py::Test::()::test_c PASSED\n"
    assert parse_summary(out) == {
        "tests/test_x.py::test_a": "PASSED",
        "tests/test_x.py::test_b": "FAILED",
        "tests/test_x.py::Test::()::test_c": "PASSED",
    }


def test_ids_holding_spaces_brackets_and_dashes() -> None:
    """A parametrized id keeps its spaces and `` - `` inside its brackets; a wanted id is matched
    whole (the longest that fits), in verbose and summary lines alike."""
    out = "\n".join(
        [
            "t.py::test_p[a b] PASSED                                                [ 25%]",
            "t.py::test_p[a] FAILED                                                  [ 50%]",
            "t.py::test_q[x - y] PASSED                                              [ 75%]",
            "t.py::test_r[1 - 2] PASSED                                              [100%]",
            "PASSED t.py::test_s[it's [nested] ok]",
            "FAILED t.py::test_u[one two] - assert 0",
        ]
    )
    assert parse_summary(out) == {
        "t.py::test_p[a b]": "PASSED",
        "t.py::test_p[a]": "FAILED",
        "t.py::test_q[x - y]": "PASSED",
        "t.py::test_r[1 - 2]": "PASSED",
        "t.py::test_s[it's [nested] ok]": "PASSED",
        "t.py::test_u[one two]": "FAILED",
    }
    # an id pytest ends at a space (no brackets) is found by the wanted id it names
    odd = "PASSED t.py::test_v with space\nt.py::test_w a b FAILED [100%]"
    assert parse_summary(odd, ("t.py::test_v with space", "t.py::test_w a b")) == {
        "t.py::test_v with space": "PASSED",
        "t.py::test_w a b": "FAILED",
    }
    # without them: a summary line's id ends at the first space (a message may follow it); the text
    # before a verbose line's status must be one id, so that line is no test
    assert read_pytest_log(odd) == {"t.py::test_v": "PASSED"}


HARNESS_OUTPUT = """+ git apply -v -
Checking patch tests/test_x.py...
Applied patch tests/test_x.py cleanly.
+ : '>>>>> Start Test Output'
+ pytest -rA tests/test_x.py
=========================== short test summary info ============================
FAILED tests/test_x.py::test_new - assert 1 == 2
PASSED tests/test_x.py::test_old
+ : '>>>>> End Test Output'
+ git checkout abc tests/test_x.py
PASSED tests/test_x.py::test_new
"""


def _inst(repo: str, f2p: tuple[str, ...], p2p: tuple[str, ...] = ()) -> SweInstance:
    return SweInstance("x__y-1", repo, "0" * 40, "", f2p, p2p, "", "", "")


def test_a_harness_log_is_read_between_its_markers() -> None:
    """The eval script's output is read where the harness reads it: between its markers (a line
    after the end marker is no result); a log without them (harness 2.x) is read whole."""
    assert harness_test_section(HARNESS_OUTPUT) == (
        "'\n+ pytest -rA tests/test_x.py\n"
        "=========================== short test summary info ============================\n"
        "FAILED tests/test_x.py::test_new - assert 1 == 2\n"
        "PASSED tests/test_x.py::test_old\n"
        "+ : '"
    )
    inst = _inst("me/mine", ("tests/test_x.py::test_new",), ("tests/test_x.py::test_old",))
    assert read_tests(inst, HARNESS_OUTPUT) == {"tests/test_x.py::test_new": "FAILED", "tests/test_x.py::test_old": "PASSED"}
    assert harness_test_section("PASSED t.py::a\n") == "PASSED t.py::a\n"
    # a run cut short (only the start marker) or a failure code: the harness reads no result
    cut = HARNESS_OUTPUT.split("+ : '>>>>> End Test Output'")[0]
    timed_out = HARNESS_OUTPUT + "\n>>>>> Tests Timed Out\n"
    assert (harness_test_section(cut), harness_test_section(timed_out)) == ("", "")
    assert read_tests(inst, cut) == {"tests/test_x.py::test_new": "MISSING", "tests/test_x.py::test_old": "MISSING"}


def test_the_official_grade_keeps_an_eval_scripts_own_markers() -> None:
    """Framing an eval script's output once more would hand the harness the text before its own
    start marker (the patch being applied): it keeps its markers instead."""
    pytest.importorskip("swebench")
    assert harness_log(HARNESS_OUTPUT, patch_applied=True) == HARNESS_OUTPUT
    inst = _inst("pytest-dev/pytest", ("tests/test_x.py::test_new",), ("tests/test_x.py::test_old",))
    grade = official_grade(inst, HARNESS_OUTPUT, patch_applied=True)
    assert (grade.resolved, grade.status, dict(grade.tests)) == (
        False,
        "RESOLVED_NO",
        {"tests/test_x.py::test_new": "FAILED", "tests/test_x.py::test_old": "PASSED"},
    )


DJANGO_OUTPUT = """+ : '>>>>> Start Test Output'
+ ./tests/runtests.py --verbosity 2 --settings=test_sqlite --parallel 1 auth_tests.test_forms
test_bug_19349_render_with_none_value (auth_tests.test_forms.ReadOnlyPasswordHashTest) ... ok
test_readonly_field_has_changed (auth_tests.test_forms.ReadOnlyPasswordHashTest) ... FAIL
test_success (auth_tests.test_forms.PasswordChangeFormTest) ... skipped 'no'
+ : '>>>>> End Test Output'
"""


def test_a_swebench_repository_is_read_by_its_own_parser() -> None:
    """Django's runner prints no pytest line: its log is read by the harness's Django parser; the
    same log under a repository SWE-bench does not know goes to our pytest reader (nothing)."""
    pytest.importorskip("swebench")
    f2p = ("test_readonly_field_has_changed (auth_tests.test_forms.ReadOnlyPasswordHashTest)",)
    p2p = (
        "test_bug_19349_render_with_none_value (auth_tests.test_forms.ReadOnlyPasswordHashTest)",
        "test_success (auth_tests.test_forms.PasswordChangeFormTest)",
    )
    assert read_tests(_inst("django/django", f2p, p2p), DJANGO_OUTPUT) == {f2p[0]: "FAILED", p2p[0]: "PASSED", p2p[1]: "SKIPPED"}
    assert read_tests(_inst("me/mine", f2p, p2p), DJANGO_OUTPUT) == {t: "MISSING" for t in (*f2p, *p2p)}
