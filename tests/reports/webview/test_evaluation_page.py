"""A coding episode's page shows how its submission was judged (issue 36 item 7): the verdict and reason,
the graders, each listed test's status coloured, the diff and the test log, exactly as its ``evaluations``
row holds them; an episode without such a row shows no evaluation. Over HTTP on the SWE run of
tests/doubles/swe_run.py, plus one evaluation row with tests, a diff and a log of its own."""

from __future__ import annotations

import html
import json
import re
import urllib.request
from pathlib import Path

import pytest

from reports.webview.server import serve, stop
from schemas.parts import PartWriter
from schemas.records import EvaluationRecord
from tests.doubles.swe_run import RUN_ID, write_swe_run

JUDGED = "swe-verified-react-django__django-4-1"  # json_failures in the double, never evaluated there
UNJUDGED = "swe-verified-react-django__django-2-1"
TESTS = {"tests/test_a.py::test_new": "FAILED", "tests/test_a.py::test_old": "PASSED", "tests/test_b.py::test_kept": "ERROR"}
PATCH = "--- a/m.py\n+++ b/m.py\n@@ -1,2 +1,2 @@\n-x = 1\n+x = 2\n keep = <3>\n"
LOG = "collected 3 items\nFAILED tests/test_a.py::test_new - assert 1 == 2\n"


@pytest.fixture(scope="module")
def viewer(tmp_path_factory):
    folder = write_swe_run(tmp_path_factory.mktemp("view_swe") / "runS")
    row = EvaluationRecord(
        episode_id=JUDGED,
        instance_id="django__django-4",
        resolved=False,
        reason="tests_failed",
        graded_by="official",
        grading="both",
        ours_resolved=True,
        tests=json.dumps(TESTS, sort_keys=True),
        fail_to_pass_passed=0,
        fail_to_pass_total=1,
        pass_to_pass_passed=1,
        pass_to_pass_total=2,
        patch=PATCH,
        patch_bytes=len(PATCH),
        log=LOG,
        log_bytes=5000,
        duration_s=12.5,
        official_resolved=False,
        official_status="RESOLVED_NO",
        official_parser="parse_log_django",
    )
    PartWriter(Path(folder), writer="viewT").write_records(RUN_ID, [row])
    server, thread = serve([folder], 0, poll_s=0)
    yield server
    stop(server, thread)


def page(server, eid: str) -> str:
    with urllib.request.urlopen(f"{server.url}episode?run={RUN_ID}&id={eid}", timeout=30) as r:
        return r.read().decode()


def text(fragment: str) -> str:
    return html.unescape(re.sub(r"<[^>]+>", "", fragment))


def test_judged_episode_shows_verdict_graders_tests_diff_and_log(viewer):
    body = page(viewer, JUDGED)
    section = re.search(r'<section id="evaluation".*?</section>', body, re.S)
    assert section is not None
    s = section.group(0)
    assert 'data-resolved="false" data-reason="tests_failed"' in s
    assert text(re.search(r"<h2>.*?</h2>", s).group(0)) == "Evaluation not resolved: tests_failed"
    assert text(re.search(r'<p class="graders">.*?</p>', s).group(0)) == (
        "deciding grader: official (grading both) · ours: resolved · "
        "official harness: not resolved (RESOLVED_NO), parser parse_log_django"
    )
    assert text(re.search(r'<p class="counts">.*?</p>', s).group(0)) == (
        "FAIL_TO_PASS 0/1 passed · PASS_TO_PASS 1/2 passed · evaluated in 12.5 s"
    )
    # every listed test with its status, failing ones (red) first, passing ones (green) after
    rows = re.findall(r'<tr class="(pass|fail)" data-test="([^"]+)"><td><code>[^<]+</code></td><td>([^<]+)</td></tr>', s)
    assert rows == [
        ("fail", "tests/test_a.py::test_new", "FAILED"),
        ("fail", "tests/test_b.py::test_kept", "ERROR"),
        ("pass", "tests/test_a.py::test_old", "PASSED"),
    ]
    # the diff line by line: removed red, added green, the rest plain; escaped
    diff = re.search(r'<pre class="diff" id="eval-patch">(.*?)</pre>', s, re.S).group(1)
    assert diff.split("\n") == [
        '<span class="same">--- a/m.py</span>',
        '<span class="same">+++ b/m.py</span>',
        '<span class="same">@@ -1,2 +1,2 @@</span>',
        "<del>-x = 1</del>",
        "<ins>+x = 2</ins>",
        '<span class="same"> keep = &lt;3&gt;</span>',
    ]
    assert text(re.search(r'<details class="log"><summary>.*?</summary>', s).group(0)) == (
        f"test log (5,000 bytes, the last {len(LOG)} kept)"
    )
    assert html.unescape(re.search(r'<pre id="eval-log">(.*?)</pre>', s, re.S).group(1)) == LOG
    # the verdict comes before the context tree and the actions
    assert body.index('id="evaluation"') < body.index('id="tree"') < body.index('id="steps"')


def test_episode_without_evaluation_row_shows_none(viewer):
    body = page(viewer, UNJUDGED)
    assert 'id="episode"' in body and 'id="evaluation"' not in body
