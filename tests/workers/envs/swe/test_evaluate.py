"""The verdict on a patch, on a clean copy: gold resolves, and each way of failing has its reason."""

from __future__ import annotations

import subprocess

from tests.workers.envs.swe.sandbox_log import SandboxLog
from workers.envs.swe.evaluate import Evaluation, eval_command, evaluate, parse_summary, patch_files
from workers.envs.swe.examples import Fixtures
from workers.envs.swe.instances import SweInstance, load_instances
from workers.sandbox.base import SandboxSpec


def _instance(fixtures: Fixtures, name: str) -> SweInstance:
    return next(i for i in load_instances(fixtures.tasks_file) if i.instance_id == f"fixture__{name}-1")


def _evaluate(inst: SweInstance, patch: str, log: SandboxLog) -> Evaluation:
    return evaluate(inst, patch, lambda: log(SandboxSpec(inst.repo_path, inst.base_commit)))


def test_gold_patch_resolves_every_fixture(fixtures: Fixtures, sandboxes: SandboxLog) -> None:
    results = {i.instance_id: _evaluate(i, i.patch, sandboxes) for i in load_instances(fixtures.tasks_file)}
    assert {k: (e.resolved, e.reason) for k, e in results.items()} == {
        "fixture__offbyone-1": (True, "resolved"),
        "fixture__format-1": (True, "resolved"),
        "fixture__twofiles-1": (True, "resolved"),
        "fixture__newfunc-1": (True, "resolved"),
        "fixture__hang-1": (True, "resolved"),
        "fixture__p2p-1": (True, "resolved"),
    }
    assert dict(results["fixture__twofiles-1"].tests) == {
        "tests/test_convert.py::test_inches_to_cm": "PASSED",
        "tests/test_convert.py::test_cm_to_inches": "PASSED",
        "tests/test_convert.py::test_zero": "PASSED",
    }
    assert all(box.closed for box in sandboxes.opened)
    assert len(sandboxes.opened) == 6


def test_empty_patch_is_no_patch_and_opens_nothing(fixtures: Fixtures, sandboxes: SandboxLog) -> None:
    ev = _evaluate(_instance(fixtures, "offbyone"), "  \n", sandboxes)
    assert (ev.resolved, ev.reason) == (False, "no_patch")
    assert dict(ev.tests) == {
        "tests/test_mathutil.py::test_count_range_inclusive": "MISSING",
        "tests/test_mathutil.py::test_total": "MISSING",
    }
    assert sandboxes.opened == []


def test_patch_that_does_not_apply_is_patch_failed(fixtures: Fixtures, sandboxes: SandboxLog) -> None:
    inst = _instance(fixtures, "offbyone")
    other = _instance(fixtures, "format").patch  # a diff of a file this repository does not have
    ev = _evaluate(inst, other, sandboxes)
    assert (ev.resolved, ev.reason) == (False, "patch_failed")
    assert "git apply --verbose .git/recap-eval-model.patch  # the model's patch" in ev.log
    assert "patch --batch --fuzz=5 -p1 -i .git/recap-eval-model.patch  # the model's patch" in ev.log


def test_hang_without_a_fix_times_out(fixtures: Fixtures, sandboxes: SandboxLog) -> None:
    ev = _evaluate(_instance(fixtures, "hang"), fixtures.wrong_patches["hang"], sandboxes)
    assert (ev.resolved, ev.reason) == (False, "timeout")
    assert sandboxes.opened[0].closed


def test_sloppy_fix_breaking_pass_to_pass_is_tests_failed(fixtures: Fixtures, sandboxes: SandboxLog) -> None:
    ev = _evaluate(_instance(fixtures, "p2p"), fixtures.wrong_patches["p2p"], sandboxes)
    assert (ev.resolved, ev.reason) == (False, "tests_failed")
    assert dict(ev.tests) == {
        "tests/test_flags.py::test_variants": "PASSED",
        "tests/test_flags.py::test_false": "FAILED",
        "tests/test_flags.py::test_empty": "PASSED",
    }


def test_fail_to_pass_still_failing_is_tests_failed(fixtures: Fixtures, sandboxes: SandboxLog) -> None:
    ev = _evaluate(_instance(fixtures, "format"), fixtures.wrong_patches["format"], sandboxes)
    assert (ev.resolved, ev.reason) == (False, "tests_failed")
    assert dict(ev.tests) == {"tests/test_shop.py::test_price_two_decimals": "FAILED", "tests/test_shop.py::test_count": "PASSED"}


def test_model_edits_to_the_judged_test_files_are_undone(fixtures: Fixtures, sandboxes: SandboxLog) -> None:
    """A patch that also rewrites the test file to pass trivially is judged on the real tests."""
    inst = _instance(fixtures, "offbyone")
    cheat = (
        "diff --git a/tests/test_mathutil.py b/tests/test_mathutil.py\n"
        "--- a/tests/test_mathutil.py\n+++ b/tests/test_mathutil.py\n"
        "@@ -1,5 +1,9 @@\n-from mathutil import total\n+from mathutil import count_range, total\n \n \n def test_total():\n"
        "     assert total([1, 2]) == 3\n+\n+\n+def test_count_range_inclusive():\n+    assert True\n"
    )
    ev = _evaluate(inst, cheat, sandboxes)
    assert (ev.resolved, ev.reason) == (False, "tests_failed")
    assert ev.tests["tests/test_mathutil.py::test_count_range_inclusive"] == "FAILED"


def test_parse_summary_reads_rA_lines() -> None:
    out = "\n".join(
        [
            "..F",
            "=========================== short test summary info ============================",
            "PASSED t.py::test_a",
            "FAILED t.py::test_b - AssertionError: x - y",
            "ERROR t.py::test_c[a - b] - RuntimeError",
            "SKIPPED [1] t.py:3: no",
            "XFAIL t.py::test_d - reason",
        ]
    )
    assert parse_summary(out, ("t.py::test_c[a - b]",)) == {
        "t.py::test_a": "PASSED",
        "t.py::test_b": "FAILED",
        "t.py::test_c[a - b]": "ERROR",  # a skip given by its location names no test
        "t.py::test_d": "XFAIL",
    }


def test_patch_files_and_test_command(fixtures: Fixtures) -> None:
    inst = _instance(fixtures, "twofiles")
    assert patch_files(inst.patch) == ["convert.py", "units.py"]
    assert eval_command(inst) == (
        "PYTEST_DISABLE_PLUGIN_AUTOLOAD=1 python -m pytest -q -p no:cacheprovider -rA "
        "tests/test_convert.py::test_inches_to_cm tests/test_convert.py::test_cm_to_inches tests/test_convert.py::test_zero"
    )


def test_the_fixture_repository_is_untouched(fixtures: Fixtures, sandboxes: SandboxLog) -> None:
    inst = _instance(fixtures, "offbyone")
    _evaluate(inst, inst.patch, sandboxes)
    status = subprocess.run(["git", "-C", inst.repo_path, "status", "--porcelain"], capture_output=True, text=True, check=True)
    assert status.stdout == ""
