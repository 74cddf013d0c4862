"""Whether a model's patch resolves a SWE-bench task, judged as the SWE-bench harness judges it.

On a clean copy of the repository at ``base_commit`` (a fresh sandbox, never the one the model
worked in): apply the model's diff (``git apply``, then ``patch --fuzz``, the harness's fallbacks:
swebench/harness/constants.py ``GIT_APPLY_CMDS``); put the test files the test patch touches back to
the base commit and apply the test patch (the model cannot change the tests it is judged by); run
the instance's ``test_cmd -rA`` on the FAIL_TO_PASS and PASS_TO_PASS node ids, its output written to
a file in ``.git`` (a command's output cap would cut pytest's summary, which comes last); read each
test's status from pytest's ``-rA`` short summary. Resolved iff every FAIL_TO_PASS test passed
(``PASSED`` or ``XFAIL``) and every PASS_TO_PASS test passed or was skipped, as the harness counts
them (swebench/harness/grading.py ``test_passed``, ``test_maintained``). A test run past
``eval_timeout_s`` (the environment's option, else the instance's) is not resolved.

An instance whose SWE-bench record is known (``swe-verified``) is evaluated as the harness does
instead (``eval_script``, :mod:`.harness_script`): the model's diff applied with the harness's
``GIT_APPLY_CMDS``, then the harness's own eval script (conda activation, the test patch, the
repository's test command on the test patch's directives, the markers) run whole, its output kept;
the tests' part of it (between the markers) is what both graders read (:func:`read_tests`). Only
a user's task (``benchmark: swe``, no record) runs ``test_cmd -rA <ids>``.

The same test log is also graded by the official harness's own functions (:mod:`.grading`,
``grading`` ``both``, the default, or ``official``): :attr:`Evaluation.success` is the official
verdict when that grading ran (published SWE-bench numbers are the harness's), else ours; the
two are kept side by side (``ours_resolved``, ``official``) so a disagreement shows in the data.
"""

from __future__ import annotations

import json
import logging
import re
import shlex
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Literal

from schemas.records import EVALUATION_LOG_CAP, EvaluationRecord
from workers.sandbox.base import CommandResult, Sandbox

from .grading import DEFAULT_GRADING, Grading, OfficialGrade, harness_statuses, official_grade, official_problem
from .harness_script import apply_commands
from .instances import SweInstance
from .patch_paths import patch_refusal
from .test_log import harness_test_section, read_pytest_log

log = logging.getLogger(__name__)

EvalReason = Literal["resolved", "no_patch", "patch_failed", "patch_refused", "tests_failed", "timeout"]
#: statuses the harness counts as a pass (swebench/harness/grading.py test_passed)
PASSING = ("PASSED", "XFAIL")
#: a PASS_TO_PASS test is kept when it passes or is skipped (grading.py ``test_maintained``)
MAINTAINED = (*PASSING, "SKIPPED")
#: a listed test that the summary does not name (not collected, a collection error)
MISSING = "MISSING"
#: characters of evaluation log kept on the Evaluation (the tail: pytest's summary is last); the
#: ``evaluations`` row keeps as much (schemas.records.EVALUATION_LOG_CAP)
LOG_CAP = EVALUATION_LOG_CAP
#: files the evaluation writes inside the sandbox's ``.git`` (never part of a diff)
MODEL_PATCH_FILE = ".git/recap-eval-model.patch"
TEST_PATCH_FILE = ".git/recap-eval-test.patch"
TEST_LOG_FILE = ".git/recap-eval-tests.log"
#: the harness's eval script, where the evaluation runs it (the harness copies it to ``/eval.sh``)
EVAL_SCRIPT_FILE = ".git/recap-eval-eval.sh"
_DIFF_FILE = re.compile(r"^diff --git a/(.+?) b/(.+)$")


@dataclass(frozen=True)
class Evaluation:
    """Our verdict on one patch: resolved, why (``reason``), each listed test's status and the log
    (its tail, :data:`LOG_CAP`); beside it the official grade of the same test log (``official``,
    None where it did not run) and what the record keeps (``test_output``: the test run's whole
    output; ``duration_s``)."""

    resolved: bool
    reason: EvalReason
    tests: Mapping[str, str] = field(default_factory=dict)
    log: str = ""
    official: OfficialGrade | None = None
    grading: Grading = DEFAULT_GRADING
    test_output: str = ""
    exit_code: int | None = None
    #: the whole log's size in UTF-8 bytes (``log`` holds its tail)
    log_bytes: int = 0
    #: the instance's PASS_TO_PASS ids (a skipped one is kept, not failed)
    pass_to_pass: tuple[str, ...] = ()
    duration_s: float = 0.0

    @property
    def graded_by(self) -> Literal["ours", "official"]:
        """Whose verdict :attr:`success` is: the official one when it ran and ``grading`` is not ``ours``."""
        return "official" if self.official is not None and self.grading != "ours" else "ours"

    @property
    def success(self) -> bool:
        """The verdict the episode's success is: the official grade's when it ran, else ours."""
        return self.official.resolved if self.graded_by == "official" and self.official is not None else self.resolved

    def verdict_tests(self) -> Mapping[str, str]:
        """Each listed test's status as the deciding grader (:attr:`graded_by`) read the log."""
        return self.official.tests if self.graded_by == "official" and self.official is not None else self.tests

    def failing_tests(self) -> list[str]:
        """The listed tests the deciding grader counts as failed, FAIL_TO_PASS first."""
        if self.graded_by == "official" and self.official is not None:
            return [*self.official.fail_to_pass_failure, *self.official.pass_to_pass_failure]
        return [t for t, s in self.tests.items() if s not in (MAINTAINED if t in self.pass_to_pass else PASSING)]

    @property
    def verdict_reason(self) -> EvalReason:
        """:attr:`reason`, made to agree with :attr:`success` (the official grade decides ``resolved``
        or ``tests_failed`` when the tests ran)."""
        if self.reason in ("resolved", "tests_failed"):
            return "resolved" if self.success else "tests_failed"
        return self.reason


def parse_summary(output: str, wanted: tuple[str, ...] = ()) -> dict[str, str]:
    """Test statuses in pytest's ``output``, read by our own reader (:func:`.test_log.read_pytest_log`:
    ``-rA`` summary, verbose, coloured and old-pytest lines alike); a line naming one of ``wanted``
    is keyed by that id, whole (a parametrized id may hold spaces, brackets, `` - ``)."""
    return read_pytest_log(output, wanted)


def read_tests(instance: SweInstance, output: str) -> dict[str, str]:
    """Each of the instance's FAIL_TO_PASS and PASS_TO_PASS tests' status in ``output`` (a test
    run's output, or an eval script's with the harness's markers), :data:`MISSING` where the log
    does not name it. Read by the harness's own parser for the instance's repository where SWE-bench
    knows it (every SWE-bench Verified instance: Django's and SymPy's runners print no pytest line),
    else by our pytest reader (a user's task), on the part of the log the harness reads
    (:func:`.test_log.harness_test_section`)."""
    wanted = (*instance.fail_to_pass, *instance.pass_to_pass)
    found = harness_statuses(instance, output)
    if found is None:
        found = parse_summary(harness_test_section(output), wanted)
    return {t: found.get(t, MISSING) for t in wanted}


def patch_files(patch: str) -> list[str]:
    """The files a git diff touches (their ``b/`` and ``a/`` paths), in order, once each."""
    out: list[str] = []
    for line in patch.splitlines():
        m = _DIFF_FILE.match(line)
        if m:
            for name in (m.group(1), m.group(2)):
                if name not in out:
                    out.append(name)
    return out


def _tail(text: str) -> str:
    """The log's last :data:`LOG_CAP` bytes (whole UTF-8 characters), marked as cut when it was longer."""
    raw = text.encode("utf-8")
    if len(raw) <= LOG_CAP:
        return text
    return "[log cut: the last part follows]\n" + raw[-LOG_CAP:].decode("utf-8", errors="ignore")


def _apply(sandbox: Sandbox, patch: str, file: str, log: list[str], what: str) -> bool:
    """Apply ``patch`` (written to ``file``): ``git apply``, else ``patch --fuzz=5``; log each try."""
    sandbox.write_file(file, patch.encode("utf-8") if patch.endswith("\n") else (patch + "\n").encode("utf-8"))
    for cmd in (f"git apply --verbose {file}", f"patch --batch --fuzz=5 -p1 -i {file}"):
        res = sandbox.run(cmd)
        log.append(f"$ {cmd}  # {what}\n{res.output.rstrip()}\n[exit {res.exit_code}]")
        if res.exit_code == 0:
            return True
        sandbox.run("git checkout -q -- . && git clean -fdq")  # a half-applied try leaves nothing behind
    return False


def refused_evaluation(instance: SweInstance, model_patch: str) -> Evaluation | None:
    """The verdict on a model's patch that writes outside the repository (:func:`.patch_paths.patch_refusal`:
    a ``..`` or absolute path, a path into ``.git``, a symlink out of the tree), given before any
    ``git apply`` or ``patch`` runs: not resolved, reason ``patch_refused``, the log saying why.
    The model wrote it, so it is the episode's outcome, never an infrastructure failure. None for
    a patch that stays inside."""
    refusal = patch_refusal(model_patch)
    if refusal is None:
        return None
    ev = Evaluation(False, "patch_refused", {t: MISSING for t in (*instance.fail_to_pass, *instance.pass_to_pass)})
    return with_log(ev, f"the model's patch was refused before it was applied: {refusal}")


def eval_command(instance: SweInstance, eval_script: str | None = None) -> str:
    """The command the evaluation runs: with the harness's eval script (written to
    :data:`EVAL_SCRIPT_FILE`), ``/bin/bash`` on it as the harness runs ``/eval.sh``; else (a user's
    task) ``test_cmd -rA`` and every listed node id, quoted."""
    if eval_script is not None:
        return f"/bin/bash {EVAL_SCRIPT_FILE}"
    ids = " ".join(shlex.quote(t) for t in (*instance.fail_to_pass, *instance.pass_to_pass))
    return f"{instance.test_cmd} -rA {ids}"


def ours_resolved(instance: SweInstance, tests: Mapping[str, str]) -> bool:
    """Our criterion: every FAIL_TO_PASS test passed, every PASS_TO_PASS test passed or was skipped."""
    return all(tests.get(t) in PASSING for t in instance.fail_to_pass) and all(
        tests.get(t) in MAINTAINED for t in instance.pass_to_pass
    )


def evaluate(
    instance: SweInstance,
    model_patch: str,
    open_clean_sandbox: Callable[[], Sandbox],
    *,
    grading: Grading = DEFAULT_GRADING,
    eval_timeout_s: float | None = None,
    eval_script: str | None = None,
) -> Evaluation:
    """The verdict on ``model_patch`` for ``instance`` (see the module docstring); the sandbox
    ``open_clean_sandbox`` gives is closed before this returns. A sandbox failure raises SandboxError.
    ``grading``: ``ours``, ``official`` or ``both`` (:mod:`.grading`); ``both`` without the
    ``swebench`` package grades with ours alone (a warning says so). ``eval_timeout_s``: the test
    run's bound (default: the instance's). ``eval_script``: the harness's eval script of the
    instance (:func:`.harness_script.eval_script`), run instead of ``test_cmd -rA <ids>``."""
    started = time.monotonic()
    timeout_s = eval_timeout_s if eval_timeout_s is not None else instance.eval_timeout_s
    ev = _evaluate(instance, model_patch, open_clean_sandbox, timeout_s=timeout_s, eval_script=eval_script)
    official: OfficialGrade | None = None
    if grading != "ours":
        problem = official_problem()
        if problem is None:
            ran = ev.reason in ("resolved", "tests_failed", "timeout")  # the patches applied, the tests ran
            official = official_grade(
                instance, ev.test_output, patch_applied=ran, timed_out=ev.reason == "timeout", exit_code=ev.exit_code
            )
        elif grading == "official":
            raise RuntimeError(problem)
        else:
            _warn_once(problem)
    return replace(
        ev,
        official=official,
        grading=grading,
        pass_to_pass=instance.pass_to_pass,
        duration_s=time.monotonic() - started,
    )


def evaluation_record(episode_id: str, instance: SweInstance, ev: Evaluation, patch: str) -> EvaluationRecord:
    """The ``evaluations`` row of one judged submission (:class:`~schemas.records.EvaluationRecord`):
    the deciding verdict, both graders' verdicts, the deciding grader's per-test statuses and
    counts, the diff and the log (its tail past :data:`~schemas.records.EVALUATION_LOG_CAP` bytes)."""
    tests = ev.verdict_tests()
    o = ev.official if ev.graded_by == "official" else None
    if o is not None:
        f2p_passed, p2p_passed = len(o.fail_to_pass_success), len(o.pass_to_pass_success)
    else:
        f2p_passed = sum(tests.get(t) in PASSING for t in instance.fail_to_pass)
        p2p_passed = sum(tests.get(t) in MAINTAINED for t in instance.pass_to_pass)
    return EvaluationRecord(
        episode_id=episode_id,
        instance_id=instance.id,
        resolved=ev.success,
        reason=ev.verdict_reason,
        graded_by=ev.graded_by,
        grading=ev.grading,
        ours_resolved=ev.resolved,
        tests=json.dumps(dict(tests), sort_keys=True),
        fail_to_pass_passed=int(f2p_passed),
        fail_to_pass_total=len(instance.fail_to_pass),
        pass_to_pass_passed=int(p2p_passed),
        pass_to_pass_total=len(instance.pass_to_pass),
        patch=patch,
        patch_bytes=len(patch.encode("utf-8")),
        log=ev.log,
        log_bytes=ev.log_bytes,
        duration_s=ev.duration_s,
        official_resolved=ev.official.resolved if ev.official is not None else None,
        official_status=ev.official.status if ev.official is not None else None,
        official_parser=ev.official.parser if ev.official is not None else None,
    )


_warned: set[str] = set()


def _warn_once(problem: str) -> None:
    if problem not in _warned:
        _warned.add(problem)
        log.warning("grading 'both': only our evaluation runs: %s", problem)


def _evaluate(
    instance: SweInstance,
    model_patch: str,
    open_clean_sandbox: Callable[[], Sandbox],
    *,
    timeout_s: float,
    eval_script: str | None = None,
) -> Evaluation:
    """Our evaluation (the module docstring), the test run's output kept whole in ``test_output``
    (with the harness's eval script: the script's whole output, :func:`_evaluate_script`)."""
    wanted = (*instance.fail_to_pass, *instance.pass_to_pass)
    if not model_patch.strip():
        return Evaluation(False, "no_patch", {t: MISSING for t in wanted}, "")
    if (refused := refused_evaluation(instance, model_patch)) is not None:
        return refused
    if eval_script is not None:
        return _evaluate_script(instance, model_patch, open_clean_sandbox, timeout_s=timeout_s, eval_script=eval_script)
    log: list[str] = []
    with open_clean_sandbox() as sandbox:
        if not _apply(sandbox, model_patch, MODEL_PATCH_FILE, log, "the model's patch"):
            return _logged(Evaluation(False, "patch_failed", {t: MISSING for t in wanted}), log)
        files = [shlex.quote(f) for f in patch_files(instance.test_patch)]
        if files:  # the test files back at the base commit (a file the base lacks is removed)
            for f in files:
                sandbox.run(f"git checkout -q {shlex.quote(instance.base_commit)} -- {f} 2>/dev/null || rm -f {f}")
        if instance.test_patch.strip() and not _apply(sandbox, instance.test_patch, TEST_PATCH_FILE, log, "the test patch"):
            return _logged(Evaluation(False, "patch_failed", {t: MISSING for t in wanted}), log)
        res, output = _run_tests(sandbox, eval_command(instance), timeout_s, log)
    tests = read_tests(instance, output)
    if res.timed_out:
        return _logged(Evaluation(False, "timeout", tests, test_output=output, exit_code=res.exit_code), log)
    resolved = ours_resolved(instance, tests)
    reason: EvalReason = "resolved" if resolved else "tests_failed"
    return _logged(Evaluation(resolved, reason, tests, test_output=output, exit_code=res.exit_code), log)


def _run_tests(sandbox: Sandbox, cmd: str, timeout_s: float, log: list[str]) -> tuple[CommandResult, str]:
    """Run the evaluation's test command with its output in :data:`TEST_LOG_FILE` (read whole,
    past the sandbox's per-command output cap), bounded by ``timeout_s``; logged to ``log``."""
    res = sandbox.run(f"{cmd} > {TEST_LOG_FILE} 2>&1", timeout_s=timeout_s)
    try:
        output = sandbox.read_file(TEST_LOG_FILE).decode("utf-8", errors="replace")
    except FileNotFoundError:
        output = res.output
    log.append(f"$ {cmd}\n{output.rstrip()}\n[exit {res.exit_code}{', timed out' if res.timed_out else ''}]")
    return res, output


def _apply_as_harness(sandbox: Sandbox, patch: str, log: list[str]) -> bool:
    """The model's diff applied as the harness applies it (``run_instance``): written as it is,
    then each of its ``GIT_APPLY_CMDS`` in turn until one succeeds, nothing undone between tries."""
    sandbox.write_file(MODEL_PATCH_FILE, patch.encode("utf-8"))
    for cmd in apply_commands():
        res = sandbox.run(f"{cmd} {MODEL_PATCH_FILE}")
        log.append(f"$ {cmd} {MODEL_PATCH_FILE}  # the model's patch\n{res.output.rstrip()}\n[exit {res.exit_code}]")
        if res.exit_code == 0:
            return True
    return False


def _evaluate_script(
    instance: SweInstance,
    model_patch: str,
    open_clean_sandbox: Callable[[], Sandbox],
    *,
    timeout_s: float,
    eval_script: str,
) -> Evaluation:
    """The harness's evaluation in our clean sandbox (:mod:`.harness_script`): the diff applied
    as it applies it, its eval script run whole (output to :data:`TEST_LOG_FILE`, bounded by
    ``timeout_s``); that output, kept whole in ``test_output`` as the harness keeps its
    ``test_output.txt``, is read as the harness reads it (:func:`read_tests`: the part between its
    markers, by the repository's parser) here and by the official grading in :func:`evaluate`
    (which keeps its markers). The script's exit status is its last command's (the test files
    put back), not the tests': ``exit_code`` stays None."""
    wanted = (*instance.fail_to_pass, *instance.pass_to_pass)
    log: list[str] = []
    with open_clean_sandbox() as sandbox:
        if not _apply_as_harness(sandbox, model_patch, log):
            return _logged(Evaluation(False, "patch_failed", {t: MISSING for t in wanted}), log)
        sandbox.write_file(EVAL_SCRIPT_FILE, eval_script.encode("utf-8"))
        res, output = _run_tests(sandbox, eval_command(instance, eval_script), timeout_s, log)
    tests = read_tests(instance, output)
    if res.timed_out:
        return _logged(Evaluation(False, "timeout", tests, test_output=output), log)
    resolved = bool(harness_test_section(output)) and ours_resolved(instance, tests)
    reason: EvalReason = "resolved" if resolved else "tests_failed"
    return _logged(Evaluation(resolved, reason, tests, test_output=output), log)


def _logged(ev: Evaluation, log: list[str]) -> Evaluation:
    """``ev`` with the log's tail (:func:`_tail`) and the whole log's size."""
    return with_log(ev, "\n".join(log))


def with_log(ev: Evaluation, text: str) -> Evaluation:
    """``ev`` with ``text`` as its log: the tail kept (:data:`LOG_CAP`), the whole size counted."""
    return replace(ev, log=_tail(text), log_bytes=len(text.encode("utf-8")))
