"""Our evaluator with the harness's eval script, step by step, on a scripted sandbox (no Docker).

What the harness does (swebench 4.x ``run_instance``): the diff written as it is and applied with
the first of its ``GIT_APPLY_CMDS`` that succeeds, nothing undone between tries; ``/bin/bash
/eval.sh`` run whole, bounded by the timeout; its output read between the markers by the
repository's parser. The Docker tests (tests/workers/envs/swe_verified/test_harness_grading.py)
run the real thing; these pin the order, the files and the verdicts."""

from __future__ import annotations

from dataclasses import dataclass, field

from workers.envs.swe.evaluate import EVAL_SCRIPT_FILE, MODEL_PATCH_FILE, TEST_LOG_FILE, evaluate
from workers.envs.swe.instances import SweInstance
from workers.sandbox.base import CommandResult, FileSlice, Sandbox

F2P, P2P = "test_word (text_utils.tests.CapfirstTests)", "test_empty (text_utils.tests.CapfirstTests)"
PATCH = "diff --git a/djmini/text.py b/djmini/text.py\n--- a/djmini/text.py\n+++ b/djmini/text.py\n@@ -1 +1 @@\n-a\n+b\n"
SCRIPT = "#!/bin/bash\nset -uxo pipefail\n: '>>>>> Start Test Output'\n./tests/runtests.py text_utils.tests\n: '>>>>> End Test Output'\n"
RUN = f"/bin/bash {EVAL_SCRIPT_FILE} > {TEST_LOG_FILE} 2>&1"


def _output(word: str) -> str:
    """An eval script's output as the harness's test_output.txt holds it (bash -x trace, markers)."""
    return (
        "+ git status\nOn branch main\n+ : '>>>>> Start Test Output'\n"
        "+ ./tests/runtests.py --verbosity 2 --settings=test_sqlite --parallel 1 text_utils.tests\n"
        "Testing against Django installed in '/testbed/django' with up to 1 processes\n"
        "System check identified no issues (0 silenced).\n"
        f"{P2P} ... ok\n{F2P} ... {word}\n\n"
        "----------------------------------------------------------------------\nRan 2 tests in 0.001s\n\n"
        "+ : '>>>>> End Test Output'\n+ git checkout abc tests/text_utils/tests.py\n"
    )


@dataclass
class Scripted(Sandbox):
    """A sandbox answering each command by its first word(s); the eval script's run writes ``log``."""

    exits: dict[str, int]
    log: str = ""
    timed_out: bool = False
    runs: list[tuple[str, float | None]] = field(default_factory=list)
    files: dict[str, bytes] = field(default_factory=dict)
    kind = "local"  # type: ignore[assignment]
    workdir = "/testbed"

    def run(self, command: str, *, timeout_s: float | None = None) -> CommandResult:
        self.runs.append((command, timeout_s))
        if command == RUN:
            self.files[TEST_LOG_FILE] = self.log.encode()
            return CommandResult(None if self.timed_out else 0, "", 0, 0.0, timed_out=self.timed_out)
        code = next(c for prefix, c in self.exits.items() if command.startswith(prefix))
        return CommandResult(code, f"{command.split()[0]} said {code}", 0, 0.0)

    def read_file(self, path: str, *, max_bytes: int | None = None) -> bytes:
        return self.files[path]

    def read_lines(self, path: str, first: int, last: int | None, max_bytes: int) -> FileSlice:
        raise AssertionError("the harness's evaluation views no file")

    def write_file(self, path: str, data: bytes) -> None:
        self.files[path] = data

    def close(self) -> None:
        self._closed = True


def _instance() -> SweInstance:
    return SweInstance(
        instance_id="django__django-1",
        repo="django/django",
        base_commit="abc",
        problem_statement="",
        fail_to_pass=(F2P,),
        pass_to_pass=(P2P,),
        patch=PATCH,
        test_patch="",
        repo_path="",
        test_cmd="./tests/runtests.py --verbosity 2 --settings=test_sqlite --parallel 1",
        extra={"version": "4.0"},
    )


def test_the_diff_is_applied_as_the_harness_applies_it_and_its_script_runs_whole() -> None:
    box = Scripted({"git apply --verbose --reject": 1, "git apply --verbose": 1, "patch --batch": 0}, _output("ok"))
    ev = evaluate(_instance(), PATCH.rstrip("\n"), lambda: box, grading="both", eval_timeout_s=7, eval_script=SCRIPT)
    assert box.runs == [
        (f"git apply --verbose {MODEL_PATCH_FILE}", None),
        (f"git apply --verbose --reject {MODEL_PATCH_FILE}", None),
        (f"patch --batch --fuzz=5 -p1 -i {MODEL_PATCH_FILE}", None),
        (RUN, 7),
    ]
    assert box.files[MODEL_PATCH_FILE] == PATCH.rstrip("\n").encode()  # as it is, as the harness writes it
    assert box.files[EVAL_SCRIPT_FILE] == SCRIPT.encode()
    assert box.closed
    assert (ev.success, ev.graded_by, ev.verdict_reason, ev.resolved) == (True, "official", "resolved", True)
    assert dict(ev.tests) == {F2P: "PASSED", P2P: "PASSED"}
    assert ev.official is not None and (ev.official.status, ev.official.parser) == ("RESOLVED_FULL", "parse_log_django")
    assert ev.test_output == _output("ok") and ev.exit_code is None


def test_a_failing_test_is_tests_failed_by_both_readers() -> None:
    box = Scripted({"git apply": 0}, _output("FAIL"))
    ev = evaluate(_instance(), PATCH, lambda: box, grading="both", eval_script=SCRIPT)
    assert box.runs[-1] == (RUN, 1800.0)  # the instance's bound when the environment sets none
    assert (ev.success, ev.verdict_reason, ev.resolved) == (False, "tests_failed", False)
    assert dict(ev.tests) == {F2P: "FAILED", P2P: "PASSED"}
    assert ev.official is not None and ev.official.fail_to_pass_failure == (F2P,)


def test_a_diff_no_command_applies_runs_no_script() -> None:
    box = Scripted({"git apply": 1, "patch": 1})
    ev = evaluate(_instance(), PATCH, lambda: box, grading="both", eval_script=SCRIPT)
    assert [c for c, _ in box.runs] == [
        f"git apply --verbose {MODEL_PATCH_FILE}",
        f"git apply --verbose --reject {MODEL_PATCH_FILE}",
        f"patch --batch --fuzz=5 -p1 -i {MODEL_PATCH_FILE}",
    ]
    assert EVAL_SCRIPT_FILE not in box.files
    assert (ev.success, ev.verdict_reason) == (False, "patch_failed")
    assert ev.official is not None and ev.official.status is None


def test_a_script_past_its_timeout_is_not_resolved() -> None:
    cut = _output("ok").split("+ : '>>>>> End Test Output'")[0]  # killed before the end marker
    box = Scripted({"git apply": 0}, cut, timed_out=True)
    ev = evaluate(_instance(), PATCH, lambda: box, grading="both", eval_timeout_s=3, eval_script=SCRIPT)
    assert box.runs[-1] == (RUN, 3)
    assert (ev.success, ev.verdict_reason, ev.resolved) == (False, "timeout", False)
    assert ev.official is not None and ev.official.status is None
