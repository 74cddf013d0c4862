"""Whether a model's patch resolves a SWE-bench task, judged as the SWE-bench harness judges it.

On a clean copy of the repository at ``base_commit`` (a fresh sandbox, never the one the model
worked in): apply the model's diff (``git apply``, then ``patch --fuzz``, the harness's fallbacks:
swebench/harness/constants.py ``GIT_APPLY_CMDS``); put the test files the test patch touches back to
the base commit and apply the test patch (the model cannot change the tests it is judged by); run
the instance's ``test_cmd -rA`` on the FAIL_TO_PASS and PASS_TO_PASS node ids, its output written to
a file in ``.git`` (a command's output cap would cut pytest's summary, which comes last); read each
test's status from pytest's ``-rA`` short summary. Resolved iff every listed test passed (``PASSED``
or ``XFAIL``, as the harness counts them). A test run past ``eval_timeout_s`` is not resolved.
"""

from __future__ import annotations

import re
import shlex
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Literal

from workers.sandbox.base import Sandbox

from .instances import SweInstance

EvalReason = Literal["resolved", "no_patch", "patch_failed", "tests_failed", "timeout"]
#: statuses the harness counts as a pass (swebench/harness/grading.py test_passed)
PASSING = ("PASSED", "XFAIL")
#: a listed test that the summary does not name (not collected, a collection error)
MISSING = "MISSING"
#: bytes of evaluation log kept on the Evaluation (the tail: pytest's summary is last)
LOG_CAP = 20_000
#: files the evaluation writes inside the sandbox's ``.git`` (never part of a diff)
MODEL_PATCH_FILE = ".git/recap-eval-model.patch"
TEST_PATCH_FILE = ".git/recap-eval-test.patch"
TEST_LOG_FILE = ".git/recap-eval-tests.log"
_SUMMARY = re.compile(r"^(PASSED|FAILED|ERROR|SKIPPED|XFAIL|XPASS) (.+)$")
_DIFF_FILE = re.compile(r"^diff --git a/(.+?) b/(.+)$")


@dataclass(frozen=True)
class Evaluation:
    """The verdict on one patch: resolved, why (``reason``), each listed test's status and the log."""

    resolved: bool
    reason: EvalReason
    tests: Mapping[str, str] = field(default_factory=dict)
    log: str = ""


def parse_summary(output: str, wanted: tuple[str, ...] = ()) -> dict[str, str]:
    """Test statuses from pytest's ``-rA`` short summary lines (``PASSED node``, ``FAILED node - msg``).
    A line naming one of ``wanted`` (exactly, or followed by `` - ``) is keyed by that id, so a node
    id holding `` - `` itself is read right; other lines by the text before `` - ``."""
    out: dict[str, str] = {}
    for line in output.splitlines():
        m = _SUMMARY.match(line.rstrip())
        if not m:
            continue
        status, rest = m.group(1), m.group(2)
        key = next((w for w in wanted if rest == w or rest.startswith(w + " - ")), None)
        out[key if key is not None else rest.split(" - ", 1)[0]] = status
    return out


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
    return text if len(text) <= LOG_CAP else "[log cut: the last part follows]\n" + text[-LOG_CAP:]


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


def eval_command(instance: SweInstance) -> str:
    """The command the evaluation runs: ``test_cmd -rA`` and every listed node id, quoted."""
    ids = " ".join(shlex.quote(t) for t in (*instance.fail_to_pass, *instance.pass_to_pass))
    return f"{instance.test_cmd} -rA {ids}"


def evaluate(instance: SweInstance, model_patch: str, open_clean_sandbox: Callable[[], Sandbox]) -> Evaluation:
    """The verdict on ``model_patch`` for ``instance`` (see the module docstring); the sandbox
    ``open_clean_sandbox`` gives is closed before this returns. A sandbox failure raises SandboxError."""
    if not model_patch.strip():
        return Evaluation(False, "no_patch", {t: MISSING for t in (*instance.fail_to_pass, *instance.pass_to_pass)}, "")
    log: list[str] = []
    wanted = (*instance.fail_to_pass, *instance.pass_to_pass)
    with open_clean_sandbox() as sandbox:
        if not _apply(sandbox, model_patch, MODEL_PATCH_FILE, log, "the model's patch"):
            return Evaluation(False, "patch_failed", {t: MISSING for t in wanted}, _tail("\n".join(log)))
        files = [shlex.quote(f) for f in patch_files(instance.test_patch)]
        if files:  # the test files back at the base commit (a file the base lacks is removed)
            for f in files:
                sandbox.run(f"git checkout -q {shlex.quote(instance.base_commit)} -- {f} 2>/dev/null || rm -f {f}")
        if instance.test_patch.strip() and not _apply(sandbox, instance.test_patch, TEST_PATCH_FILE, log, "the test patch"):
            return Evaluation(False, "patch_failed", {t: MISSING for t in wanted}, _tail("\n".join(log)))
        cmd = eval_command(instance)
        res = sandbox.run(f"{cmd} > {TEST_LOG_FILE} 2>&1", timeout_s=instance.eval_timeout_s)
        try:
            output = sandbox.read_file(TEST_LOG_FILE).decode("utf-8", errors="replace")
        except FileNotFoundError:
            output = res.output
        log.append(f"$ {cmd}\n{output.rstrip()}\n[exit {res.exit_code}{', timed out' if res.timed_out else ''}]")
    found = parse_summary(output, wanted)
    tests = {t: found.get(t, MISSING) for t in wanted}
    if res.timed_out:
        return Evaluation(False, "timeout", tests, _tail("\n".join(log)))
    resolved = all(s in PASSING for s in tests.values())
    return Evaluation(resolved, "resolved" if resolved else "tests_failed", tests, _tail("\n".join(log)))
