"""Every grader agrees with the SWE-bench harness on real harness logs.

The data: 68 ``(test_output.txt, report.json)`` pairs the harness wrote for SWE-bench Verified
instances of 11 repositories (33 resolved, 35 not), byte-exact copies of files that public
repositories committed. Fetched data is not committed here: the files live in
``../shared/data/swe-harness-logs/<pair>/`` (or ``$SWE_HARNESS_LOGS``); ``data/harness_logs_sources.json``
beside this file is our manifest of them (repository, commit, path, SHA-256, verdict) and
``data/harness_logs_sources.md`` says where they come from. Every file is checked against its
SHA-256 before it is read; without the folder the module is skipped with the reason.
67 from harness 2.x, whose eval script printed no test-output markers (the harness read the whole
log), one from 3.x/4.x, read between its markers.
For each pair the instance is rebuilt from the report itself (its ``tests_status`` lists every
FAIL_TO_PASS and PASS_TO_PASS test, as success or failure) and each grader must give the report's
``resolved``:

* the official grade: :func:`~workers.envs.swe.grading.official_grade` (the log through
  ``swebench``'s ``get_logs_eval``, ``get_eval_tests_report``, ``get_resolution_status``), with the
  report's success lists too;
* our reading for SWE-bench Verified: :func:`~workers.envs.swe.evaluate.read_tests` (the harness's
  parser for the repository) and our criterion, both on its own and as ``grading: harness``
  (:func:`~workers.envs.swe_verified.harness_eval.harness_evaluation`) sets it beside the report;
* for the repositories whose tests run under pytest, our own reader for a user's tasks
  (:func:`~workers.envs.swe.evaluate.parse_summary`) on the part of the log the harness reads.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from tests.conftest import SHARED_DATA
from workers.envs.swe.evaluate import MISSING, ours_resolved, parse_summary, read_tests
from workers.envs.swe.grading import official_grade
from workers.envs.swe.instances import SweInstance
from workers.envs.swe.test_log import harness_test_section, has_markers
from workers.envs.swe_verified.harness_eval import HarnessRun, harness_evaluation

pytest.importorskip("swebench")  # a core dependency of swe-verified; installed with recap-eval[swe]

#: our manifest of the pairs (committed); the pairs themselves are shared data
SOURCES: list[dict[str, Any]] = json.loads((Path(__file__).with_name("data") / "harness_logs_sources.json").read_text())
DATA = Path(os.environ.get("SWE_HARNESS_LOGS") or SHARED_DATA / "swe-harness-logs")
if not DATA.is_dir():
    pytest.skip(f"{DATA} is absent (the real harness logs, data/harness_logs_sources.md)", allow_module_level=True)
#: repositories whose test command is not pytest (their logs have no pytest lines)
NOT_PYTEST = {"django/django", "sympy/sympy"}


@dataclass(frozen=True)
class Pair:
    name: str
    instance: SweInstance
    log: str
    report: dict[str, Any]

    @property
    def resolved(self) -> bool:
        return bool(self.report["resolved"])


def _repo(instance_id: str) -> str:
    owner, rest = instance_id.split("__", 1)
    return f"{owner}/{rest.rsplit('-', 1)[0]}"


def _load(entry: dict[str, Any]) -> Pair:
    folder = DATA / entry["pair"]
    raw = (folder / "test_output.txt").read_bytes()
    report_bytes = (folder / "report.json").read_bytes()
    for stored, data in (("test_output.txt", raw), ("report.json", report_bytes)):  # byte-exact copies
        assert hashlib.sha256(data).hexdigest() == entry["files"][stored]["sha256"], (entry["pair"], stored)
    iid = entry["instance_id"]
    report = json.loads(report_bytes)[iid]
    status = report["tests_status"]
    f2p = (*status["FAIL_TO_PASS"]["success"], *status["FAIL_TO_PASS"]["failure"])
    p2p = (*status["PASS_TO_PASS"]["success"], *status["PASS_TO_PASS"]["failure"])
    instance = SweInstance(
        instance_id=iid,
        repo=_repo(iid),
        base_commit="0" * 40,
        problem_statement="",
        fail_to_pass=f2p,
        pass_to_pass=p2p,
        patch="",
        test_patch="",
        repo_path="",
    )
    return Pair(entry["pair"], instance, raw.decode("utf-8", errors="replace"), report)


PAIRS = [_load(e) for e in SOURCES]


def test_the_data_is_many_real_pairs_over_many_repositories_both_verdicts() -> None:
    repos = Counter(p.instance.repo for p in PAIRS)
    verdicts = Counter(p.resolved for p in PAIRS)
    assert len(PAIRS) >= 50 and len(repos) >= 8, (len(PAIRS), repos)
    assert verdicts[True] >= 20 and verdicts[False] >= 20, verdicts
    assert Counter(has_markers(p.log) for p in PAIRS) == Counter({False: 67, True: 1})  # both layouts
    assert all(p.resolved == e["resolved"] for p, e in zip(PAIRS, SOURCES, strict=True))


def _ids(pairs: list[Pair]) -> list[str]:
    return [p.name for p in pairs]


@pytest.mark.parametrize("pair", PAIRS, ids=_ids(PAIRS))
def test_every_grader_gives_the_harness_verdict(pair: Pair) -> None:
    inst, status = pair.instance, pair.report["tests_status"]
    official = official_grade(inst, pair.log, patch_applied=True)
    assert official.resolved is pair.resolved
    assert (official.status == "RESOLVED_FULL") is pair.resolved
    assert (
        sorted(official.fail_to_pass_success),
        sorted(official.pass_to_pass_success),
    ) == (sorted(status["FAIL_TO_PASS"]["success"]), sorted(status["PASS_TO_PASS"]["success"]))

    ours = read_tests(inst, pair.log)  # the harness's parser for the repository, our criterion
    assert ours_resolved(inst, ours) is pair.resolved, _failing(inst, ours)

    ev = harness_evaluation(inst, HarnessRun(pair.report, pair.log, "instance log", 0, ""))
    assert (ev.resolved, ev.success, ev.graded_by) == (pair.resolved, pair.resolved, "official")
    assert ev.tests == ours


PYTEST_PAIRS = [p for p in PAIRS if p.instance.repo not in NOT_PYTEST]


def test_the_pytest_pairs_cover_several_repositories_and_both_verdicts() -> None:
    assert len({p.instance.repo for p in PYTEST_PAIRS}) >= 8
    assert Counter(p.resolved for p in PYTEST_PAIRS) == Counter({False: 22, True: 16})


@pytest.mark.parametrize("pair", PYTEST_PAIRS, ids=_ids(PYTEST_PAIRS))
def test_our_pytest_reader_gives_the_harness_verdict(pair: Pair) -> None:
    inst = pair.instance
    wanted = (*inst.fail_to_pass, *inst.pass_to_pass)
    found = parse_summary(harness_test_section(pair.log), wanted)
    tests = {t: found.get(t, MISSING) for t in wanted}
    assert ours_resolved(inst, tests) is pair.resolved, _failing(inst, tests)


def _failing(inst: SweInstance, tests: dict[str, str]) -> list[tuple[str, str]]:
    """The listed tests our criterion fails, for the assertion message."""
    return [(t, s) for t, s in tests.items() if s not in ("PASSED", "XFAIL", *(("SKIPPED",) if t in inst.pass_to_pass else ()))]
