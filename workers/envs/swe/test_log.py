"""Reading test statuses out of a test run's log: the part of a harness log the harness reads, and
our own pytest reader for the tasks SWE-bench has no parser for (a user's ``benchmark: swe`` tasks).

Where the repository is one SWE-bench knows, its own per-repository parser reads the log
(:func:`workers.envs.swe.grading.harness_statuses`; Django's and SymPy's runners print no pytest
lines at all); this module holds what does not need the ``swebench`` package:

* :func:`harness_test_section`: the part of an eval script's output the harness parses. The
  harness's eval script (``swebench`` 3.x-4.x) prints ``: '>>>>> Start Test Output'`` and
  ``: '>>>>> End Test Output'`` around the test command, and its ``get_logs_eval``
  (swebench/harness/grading.py, 4.1.0 lines 39-91) parses what lies between them, the whole log
  when that gives no status. Harness 2.x's eval script printed no markers and its
  ``get_logs_eval`` (tag v2.0.13, grading.py:34-74) parsed the whole log; a log with neither
  marker is read whole here too.
* :func:`read_pytest_log`: each test's status as pytest reports it, whatever the options: the
  ``-rA`` short summary (``PASSED id``, ``FAILED id - message``), verbose lines
  (``id PASSED [ 10%]``, ``id SKIPPED (reason) [ 50%]``, xdist's ``[gw0] [ 10%] PASSED id``),
  old pytest's ``id PASSED`` (no percentage), coloured output (ANSI escapes removed first), and
  ids holding spaces, brackets or `` - `` (parametrized ids: a line naming one of the ``wanted``
  ids is keyed by that id, whole).
"""

from __future__ import annotations

import re
from collections.abc import Iterable

#: the statuses pytest prints for a test (``-rA`` letters ``PpsxXEf`` and the verbose words)
STATUSES = ("PASSED", "FAILED", "ERROR", "SKIPPED", "XFAIL", "XPASS")
#: the harness's eval-script markers (swebench.harness.constants START_TEST_OUTPUT / END_TEST_OUTPUT)
START_TEST_OUTPUT = ">>>>> Start Test Output"
END_TEST_OUTPUT = ">>>>> End Test Output"
#: what makes the harness read no result from a log (APPLY_PATCH_FAIL, RESET_FAILED, TESTS_ERROR,
#: TESTS_TIMEOUT of swebench.harness.constants; both 2.x's and 4.x's get_logs_eval check them)
FAILURE_CODES = (">>>>> Patch Apply Failed", ">>>>> Reset Failed", ">>>>> Tests Errored", ">>>>> Tests Timed Out")

#: an ANSI escape sequence (colour, bold, cursor) as a terminal-coloured pytest writes it
_ANSI = re.compile(r"\x1b\[[0-9;?]*[ -/]*[@-~]")
_STATUS = "|".join(STATUSES)
#: ``STATUS rest`` (the ``-rA`` summary, xdist's verbose lines once their ``[gwN] [ NN%]`` is cut)
_LEADING = re.compile(rf"^({_STATUS})(?: (.*))?$")
#: ``rest STATUS`` with an optional ``(reason)`` and ``[ NN%]`` (verbose; old pytest has neither)
_TRAILING = re.compile(rf"^(.*?) ({_STATUS})(?: \(.*\))?(?:\s+\[\s*\d+%\])?$")
_XDIST = re.compile(r"^\[gw\d+\]\s+\[\s*\d+%\]\s+")
#: a ``-rA`` SKIPPED/XFAIL line that gives a location, not a test id (``SKIPPED [1] t.py:3: why``)
_LOCATION = re.compile(r"^\[\d+\] ")


def strip_ansi(text: str) -> str:
    """``text`` without ANSI escape sequences (``\\x1b[32mPASSED\\x1b[0m`` -> ``PASSED``)."""
    return _ANSI.sub("", text)


def harness_test_section(log: str) -> str:
    """The part of an eval script's output the harness parses first: between its start and end
    markers when both are there (as ``get_logs_eval`` splits: after the first start marker, up to
    the next end marker); the whole log when neither is (harness 2.x printed no markers and read
    it whole); nothing when the log holds one of the harness's :data:`FAILURE_CODES` or only one
    of the markers (a run cut short: the harness reads no result from it)."""
    if any(code in log for code in FAILURE_CODES):
        return ""
    start, end = START_TEST_OUTPUT in log, END_TEST_OUTPUT in log
    if start and end:
        return log.split(START_TEST_OUTPUT, 1)[1].split(END_TEST_OUTPUT, 1)[0]
    return "" if start or end else log


def has_markers(log: str) -> bool:
    """Whether ``log`` carries both of the harness's test-output markers."""
    return START_TEST_OUTPUT in log and END_TEST_OUTPUT in log


def read_pytest_log(output: str, wanted: Iterable[str] = ()) -> dict[str, str]:
    """Each test's status in pytest's ``output`` (see the module doc), the last line naming a test
    deciding (pytest's ``-rA`` summary comes after its verbose lines, and lists ``ERROR`` after
    ``PASSED`` for a test whose teardown failed). A line naming one of ``wanted`` is keyed by that
    id (the longest that fits); another by the id as pytest writes it (up to the first space
    outside brackets)."""
    ids = sorted(set(wanted), key=len, reverse=True)
    out: dict[str, str] = {}
    for raw in output.splitlines():
        line = _XDIST.sub("", strip_ansi(raw).strip())
        if not line:
            continue
        m = _LEADING.match(line)
        if m:
            status, rest = m.group(1), (m.group(2) or "").strip()
            if not rest or _LOCATION.match(rest):
                continue
            key = _wanted_prefix(rest, ids, (" - ", " "))
            out[key if key is not None else _node_id(rest)] = status
            continue
        m = _TRAILING.match(line)
        if m:
            rest, status = m.group(1).strip(), m.group(2)
            key = _wanted_prefix(rest, ids, ())
            if key is None:
                node = _node_id(rest)
                if node != rest:  # text before the status is not one id: not a test line
                    continue
                key = node
            out[key] = status
    return out


def _wanted_prefix(rest: str, ids: list[str], separators: tuple[str, ...]) -> str | None:
    """The (longest) wanted id ``rest`` is, or starts with followed by one of ``separators``."""
    for w in ids:
        if rest == w or any(rest.startswith(w + sep) for sep in separators):
            return w
    return None


def _node_id(rest: str) -> str:
    """The node id at the start of ``rest``: up to the first space outside ``[...]`` (a
    parametrized id such as ``t.py::test[a b]`` holds spaces inside its brackets)."""
    depth = 0
    for i, ch in enumerate(rest):
        if ch == "[":
            depth += 1
        elif ch == "]" and depth:
            depth -= 1
        elif ch.isspace() and depth == 0:
            return rest[:i]
    return rest
