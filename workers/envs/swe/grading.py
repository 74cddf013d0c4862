"""The official SWE-bench harness's grading of a test log, beside our own (:mod:`.evaluate`).

Why both: our evaluator runs the tests and reads their log (with the harness's own parser for a
repository SWE-bench knows, :func:`harness_statuses`; our pytest reader for a user's task) and
decides by our criterion; the harness's grading of the same log is what published SWE-bench
numbers mean (a PASS_TO_PASS test that is skipped is
kept; in 5.x a truncated parametrized id matches by prefix and a run whose exit status contradicts
its log counts as no run; in 4.x, the pinned version, a skipped FAIL_TO_PASS test is no failure). So the same log goes through the
``swebench`` package's own functions (``swebench/harness/grading.py``, 4.x or 5.x):

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
import inspect
import os
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Literal

from .instances import SweInstance
from .test_log import harness_test_section, has_markers

Grading = Literal["ours", "official", "both", "harness"]
#: the grading modes: our evaluator only, the official harness's only, or both (the default);
#: SWE-bench Verified has a fourth, ``harness`` (the harness's own full Docker evaluation,
#: :mod:`workers.envs.swe_verified.harness_eval`), which needs the instance's harness image
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
    """Why the official grading cannot run here (one line), or None when ``swebench`` imports."""
    try:
        _harness()
    except ImportError as exc:
        return f"the official SWE-bench grading needs the swebench package: {INSTALL_HINT} ({exc})"
    return None


def check_grading(value: Any, choices: tuple[Grading, ...] = GRADINGS) -> Grading:
    """``value`` as one of ``choices``; ValueError (one line) for another value, or for ``official``
    or ``harness`` where ``swebench`` cannot be imported (``both`` then grades with ours alone, see
    :func:`official_grade`)."""
    if value not in choices:
        raise ValueError(f"grading must be one of {', '.join(choices)}, got {value!r}")
    if value in ("official", "harness") and (problem := official_problem()) is not None:
        raise ValueError(f"grading {value!r}: {problem}")
    return value


@lru_cache(maxsize=1)
def _harness() -> dict[str, Any]:
    """The harness's functions and constants, imported once (ImportError without ``swebench``).

    Works with swebench 4.x (what ``recap-eval[swe]`` installs: it also has each repository's test
    command, which swe-verified needs) and 5.x: the parser maps are read from the per-language
    modules both have (``MAP_REPO_TO_PARSER_PY`` ...), the parsers by name from 5.x's
    ``PARSER_REGISTRY`` or, in 4.x, from the functions themselves."""
    from swebench.harness import constants as C
    from swebench.harness import grading as G
    from swebench.harness import log_parsers as LP

    try:
        from swebench.types import TestSpec  # 5.x
    except ImportError:
        from swebench.harness.test_spec.test_spec import TestSpec  # 4.x
    from swebench.harness.log_parsers.python import parse_log_pytest

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
    if not isinstance(registry, dict):  # 4.x: no registry; a parser is named by its function
        registry = {f.__name__: f for f in by_repo.values()}
        registry.setdefault(DEFAULT_PARSER, parse_log_pytest)
    if not hasattr(G, "get_logs_eval") or not hasattr(G, "get_resolution_status"):
        raise ImportError("swebench.harness.grading lacks get_logs_eval / get_resolution_status")
    specs = getattr(C, "MAP_REPO_VERSION_TO_SPECS", None)  # 4.x only
    return {"C": C, "G": G, "TestSpec": TestSpec, "by_repo": by_repo, "registry": registry, "specs": specs}


def _test_spec(h: dict[str, Any], instance: SweInstance, parser: str) -> Any:
    """A ``TestSpec`` for grading: the fields the installed version's class takes, from the
    instance (no image, no scripts: the log is already written)."""
    C = h["C"]
    values: dict[str, Any] = {
        "instance_id": instance.instance_id,
        "repo": instance.repo,
        "version": str(instance.extra.get("version", "")),
        "FAIL_TO_PASS": list(instance.fail_to_pass),
        "PASS_TO_PASS": list(instance.pass_to_pass),
        "image": "",
        "eval_script_list": [],
        "repo_script_list": [],
        "env_script_list": [],
        "arch": "x86_64",
        "language": "py",
        "docker_specs": {},
        "namespace": None,
        "log_parser": parser,
    }
    if hasattr(C, "EvalType"):
        values["eval_type"] = C.EvalType.PASS_AND_FAIL.value
    accepted = inspect.signature(h["TestSpec"]).parameters
    return h["TestSpec"](**{k: v for k, v in values.items() if k in accepted})


def _logs_eval(h: dict[str, Any], spec: Any, instance: SweInstance, parser: str, path: str) -> tuple[dict[str, str], bool]:
    """The harness's ``get_logs_eval`` on the framed log. swebench 4.x's looks the parser and the
    test command up by repository and version, so for a repository it does not know (our
    fixtures, a user's tasks) its same steps run here with its own markers and
    ``parse_log_pytest``: a log with a failure marker, or without the test-output markers, has no
    results; else the parser reads the output between the markers (the whole log when that gives
    nothing)."""
    C, G = h["C"], h["G"]
    specs = h["specs"]
    if specs is None or spec.version in specs.get(instance.repo, {}):
        return G.get_logs_eval(spec, path)
    with open(path, encoding="utf-8") as fh:
        content = fh.read()
    if any(code in content for code in (C.APPLY_PATCH_FAIL, C.RESET_FAILED, C.TESTS_ERROR, C.TESTS_TIMEOUT)):
        return {}, False
    if not (C.START_TEST_OUTPUT in content and C.END_TEST_OUTPUT in content):
        return {}, False
    parse = h["registry"][parser]
    status_map = parse(content.split(C.START_TEST_OUTPUT)[1].split(C.END_TEST_OUTPUT)[0], spec)
    return (status_map or parse(content, spec)), True


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


def harness_parser(repo: str) -> Callable[..., dict[str, str]] | None:
    """The harness's own log parser for ``repo`` (``MAP_REPO_TO_PARSER_*``), or None where SWE-bench
    does not know the repository or the ``swebench`` package is not installed (a user's task:
    our pytest reader, :func:`.test_log.read_pytest_log`, reads its log)."""
    try:
        h = _harness()
    except ImportError:
        return None
    fn = h["by_repo"].get(repo)
    return fn if callable(fn) else None


def harness_statuses(instance: SweInstance, log: str) -> dict[str, str] | None:
    """Each test's status in ``log`` (a test run's output, or a whole eval-script output with the
    harness's markers) as the harness's parser for ``instance.repo`` reads it: the section between
    the markers (:func:`.test_log.harness_test_section`), the whole log when that section gives
    none, as ``get_logs_eval`` does (swebench/harness/grading.py 4.1.0:79-89). None where the
    repository has no harness parser (:func:`harness_parser`)."""
    parse = harness_parser(instance.repo)
    if parse is None:
        return None
    spec = _test_spec(_harness(), instance, parser_name(instance.repo))
    section = harness_test_section(log)
    found = parse(section, spec) if section else {}
    if not found and section and has_markers(log):
        found = parse(log, spec)
    return {str(k): str(v) for k, v in found.items()}


def harness_log(test_log: str, *, patch_applied: bool, timed_out: bool = False, exit_code: int | None = None) -> str:
    """``test_log`` framed as the harness's eval script and run_evaluation.py write it (markers of
    ``swebench.harness.constants``). A log that is already an eval script's output (both markers
    in it: the harness's ``test_output.txt``) keeps its own markers, so the harness reads the same
    section of it as when it wrote it; a harness 2.x log (no markers: that harness read the whole
    log, grading.py:34-74 at tag v2.0.13) is framed whole."""
    C = _harness()["C"]
    if not patch_applied:
        return f"{C.APPLY_PATCH_FAIL}:\n{test_log}\n"
    if C.START_TEST_OUTPUT in test_log and C.END_TEST_OUTPUT in test_log:
        out = f"{test_log.rstrip()}\n"
    else:
        out = f"{C.START_TEST_OUTPUT}\n{test_log.rstrip()}\n{C.END_TEST_OUTPUT}\n"
    if exit_code is not None and not timed_out and hasattr(C, "TEST_EXIT_CODE"):  # 5.x cross-checks it
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
    spec = _test_spec(h, instance, name)
    content = harness_log(test_log, patch_applied=patch_applied, timed_out=timed_out, exit_code=exit_code)
    fd, path = tempfile.mkstemp(prefix="recap-eval-swe-", suffix=".log")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(content)
        status_map, found = _logs_eval(h, spec, instance, name, path)
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
