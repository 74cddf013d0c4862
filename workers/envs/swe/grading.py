"""The official SWE-bench harness's grading of a test log, beside our own (:mod:`.evaluate`).

Why both: our evaluator runs the tests and reads pytest's ``-rA`` summary; the harness's reading
of the same log is what published SWE-bench numbers mean (a PASS_TO_PASS test that is skipped is
kept, a FAIL_TO_PASS one that is skipped is not, a truncated parametrized id matches by prefix, a
run whose exit status contradicts its log counts as no run). So the same log goes through the
``swebench`` package's own functions (swebench 5.x, ``swebench/harness/grading.py``):

* the log is framed as the harness's eval script frames it (``START_TEST_OUTPUT`` /
  ``END_TEST_OUTPUT``, then ``TEST_EXIT_CODE: n``; ``APPLY_PATCH_FAIL`` when the patch did not
  apply, ``TESTS_TIMEOUT`` when the run was killed) and read by ``get_logs_eval``;
* with the log parser of the instance's repository when it is a SWE-bench repository
  (``MAP_REPO_TO_PARSER_*`` of ``swebench/harness/log_parsers``: ``django/django`` reads
  Django's runner lines, ``sympy/sympy`` sympy's), else ``parse_log_pytest`` (our fixture tasks,
  a user's tasks: pytest's ``-rA`` lines);
* ``get_eval_tests_report`` gives each FAIL_TO_PASS / PASS_TO_PASS test's success or failure,
  ``get_resolution_status`` the status (``RESOLVED_FULL`` / ``RESOLVED_PARTIAL`` /
  ``RESOLVED_NO``); resolved iff FULL.

Where the harness writes no report (an empty patch, which it skips; a patch that does not apply;
a test run past its timeout; a log with no test results) the grade is not resolved and its
``status`` is None, as the harness's report has no resolution status then.

``swebench`` is an optional dependency (``pip install 'recap-eval[swe]'``: it pulls datasets,
modal, GitPython...), imported only here and only when a grade is asked for.
"""

from __future__ import annotations

import importlib
import os
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Literal

from .instances import SweInstance

Grading = Literal["ours", "official", "both"]
#: the grading modes: our evaluator only, the official harness's only, or both (the default)
GRADINGS: tuple[Grading, ...] = ("ours", "official", "both")
DEFAULT_GRADING: Grading = "both"
#: a listed test the parser did not report (as :data:`.evaluate.MISSING`)
MISSING = "MISSING"
#: the parser for a repository SWE-bench does not know: pytest's ``-rA`` lines
DEFAULT_PARSER = "parse_log_pytest"
INSTALL_HINT = "pip install 'recap-eval[swe]'"


@dataclass(frozen=True)
class OfficialGrade:
    """The harness's verdict on one test log: ``resolved`` (status FULL), ``status`` (None where the
    harness writes no report), each listed test's status as the repository's parser read it
    (``tests``, :data:`MISSING` when not read) and the report's success/failure lists."""

    resolved: bool
    status: str | None
    parser: str
    tests: Mapping[str, str] = field(default_factory=dict)
    fail_to_pass_success: tuple[str, ...] = ()
    fail_to_pass_failure: tuple[str, ...] = ()
    pass_to_pass_success: tuple[str, ...] = ()
    pass_to_pass_failure: tuple[str, ...] = ()


def official_problem() -> str | None:
    """Why the official grading cannot run here (one line), or None when ``swebench`` 5.x imports."""
    try:
        _harness()
    except ImportError as exc:
        return f"the official SWE-bench grading needs the swebench package (5.x): {INSTALL_HINT} ({exc})"
    return None


def check_grading(value: Any) -> Grading:
    """``value`` as a grading mode; ValueError (one line) for another value, or for ``official``
    where ``swebench`` cannot be imported (``both`` then grades with ours alone, see :func:`official_grade`)."""
    if value not in GRADINGS:
        raise ValueError(f"grading must be one of {', '.join(GRADINGS)}, got {value!r}")
    if value == "official" and (problem := official_problem()) is not None:
        raise ValueError(f"grading 'official': {problem}")
    return value


@lru_cache(maxsize=1)
def _harness() -> dict[str, Any]:
    """The harness's functions and constants (imported once; ImportError without swebench 5.x)."""
    from swebench.harness import constants as C
    from swebench.harness import grading as G
    from swebench.harness import log_parsers as LP
    from swebench.types import TestSpec

    by_repo: dict[str, Any] = {}
    for lang in ("python", "javascript", "c", "go", "java", "php", "ruby", "rust"):
        try:
            mod = importlib.import_module(f"swebench.harness.log_parsers.{lang}")
        except ImportError:
            continue
        for name in dir(mod):
            if name.startswith("MAP_REPO_TO_PARSER_"):
                by_repo.update(getattr(mod, name))
    registry = getattr(LP, "PARSER_REGISTRY", None)
    if not isinstance(registry, dict) or not hasattr(G, "get_logs_eval"):
        raise ImportError("swebench.harness.log_parsers.PARSER_REGISTRY is missing (swebench 5.x is needed)")
    return {"C": C, "G": G, "TestSpec": TestSpec, "by_repo": by_repo, "registry": registry}


def parser_name(repo: str) -> str:
    """The name (``PARSER_REGISTRY``) of the log parser the harness uses for ``repo``
    (``django/django`` -> ``parse_log_django``); :data:`DEFAULT_PARSER` for a repository it does not know."""
    h = _harness()
    fn = h["by_repo"].get(repo)
    names = [name for name, f in h["registry"].items() if f is fn] if fn is not None else []
    if not names:
        return DEFAULT_PARSER
    # several names may hold one function (parse_log_astropy = parse_log_pytest_v2): the repository's own first
    own = f"parse_log_{repo.rsplit('/', 1)[-1].replace('-', '_')}"
    return own if own in names else str(names[0])


def harness_log(test_log: str, *, patch_applied: bool, timed_out: bool = False, exit_code: int | None = None) -> str:
    """``test_log`` framed as the harness's eval script and run_evaluation.py write it (markers of
    ``swebench.harness.constants``)."""
    C = _harness()["C"]
    if not patch_applied:
        return f"{C.APPLY_PATCH_FAIL}:\n{test_log}\n"
    out = f"{C.START_TEST_OUTPUT}\n{test_log.rstrip()}\n{C.END_TEST_OUTPUT}\n"
    if exit_code is not None and not timed_out:
        out += f"{C.TEST_EXIT_CODE}: {exit_code}\n"
    if timed_out:
        out += f"\n{C.TESTS_TIMEOUT}\n"
    return out


def official_grade(
    instance: SweInstance, test_log: str, *, patch_applied: bool, timed_out: bool = False, exit_code: int | None = None
) -> OfficialGrade:
    """The harness's grade of ``test_log``, the output of the instance's test run (see the module
    doc). ``patch_applied`` False: the patch (or the test patch) did not apply, or there was none;
    ``timed_out``: the run was killed at its timeout; ``exit_code``: the test command's exit status
    (the harness cross-checks it against the log). ImportError without ``swebench``."""
    h = _harness()
    C, G = h["C"], h["G"]
    name = parser_name(instance.repo)
    f2p, p2p = list(instance.fail_to_pass), list(instance.pass_to_pass)
    spec = h["TestSpec"](
        instance_id=instance.instance_id,
        image="",
        eval_script_list=[],
        repo=instance.repo,
        version=str(instance.extra.get("version", "")),
        FAIL_TO_PASS=f2p,
        PASS_TO_PASS=p2p,
        log_parser=name,
        eval_type=C.EvalType.PASS_AND_FAIL.value,
    )
    content = harness_log(test_log, patch_applied=patch_applied, timed_out=timed_out, exit_code=exit_code)
    fd, path = tempfile.mkstemp(prefix="recap-eval-swe-", suffix=".log")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(content)
        status_map, found = G.get_logs_eval(spec, path)
    finally:
        os.unlink(path)
    tests = {t: _status_of(G, t, status_map) for t in (*f2p, *p2p)}
    if not found:
        return OfficialGrade(False, None, name, tests)
    report = G.get_eval_tests_report(status_map, {C.FAIL_TO_PASS: f2p, C.PASS_TO_PASS: p2p}, eval_type=C.EvalType.PASS_AND_FAIL)
    status = str(G.get_resolution_status(report))
    f, p = report[C.FAIL_TO_PASS], report[C.PASS_TO_PASS]
    return OfficialGrade(
        status == C.ResolvedStatus.FULL.value,
        status,
        name,
        tests,
        tuple(f["success"]),
        tuple(f["failure"]),
        tuple(p["success"]),
        tuple(p["failure"]),
    )


def _status_of(G: Any, test: str, status_map: Mapping[str, str]) -> str:
    """The status the harness reads for ``test`` (its own id matching, ``_resolve_case`` where the
    installed version has it: a truncated parametrized id matches by prefix)."""
    resolve = getattr(G, "_resolve_case", None)
    key = resolve(test, dict(status_map)) if resolve is not None else (test if test in status_map else None)
    return MISSING if key is None else str(status_map[key])
