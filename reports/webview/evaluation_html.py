"""A coding episode's evaluation on its page (issue 36 item 7): the verdict and its reason, the grader(s)
that judged it, each listed test's status (passing green, failing red), the submitted diff and the test
log, read from its ``evaluations`` row (:class:`schemas.records.EvaluationRecord`). An episode of another
benchmark has no such row and shows no such section.

The row keeps each FAIL_TO_PASS and PASS_TO_PASS test's status in one map (``tests``) and the counts per
group; it does not say which group a test id is in, so the tests are listed once, with both groups'
counts above them."""

from __future__ import annotations

import json
from typing import Any

from reports.webview.layout import esc, num

#: statuses a grader counts as a pass (the harness's PASSED and XFAIL; our reader's the same)
PASSING = ("PASSED", "XFAIL")


def evaluation_html(ev: dict[str, Any]) -> str:
    """The section of one ``evaluations`` row: verdict line, graders, tests, diff, log."""
    verdict = "resolved" if ev["resolved"] else f"not resolved: {ev['reason']}"
    graders = [f"deciding grader: {esc(ev['graded_by'])} (grading {esc(ev['grading'])})"]
    graders.append(f"ours: {'resolved' if ev['ours_resolved'] else 'not resolved'}")
    if ev.get("official_resolved") is not None or ev.get("official_status"):
        official = "resolved" if ev.get("official_resolved") else "not resolved"
        graders.append(
            f"official harness: {official}"
            + (f" ({esc(ev['official_status'])})" if ev.get("official_status") else "")
            + (f", parser {esc(ev['official_parser'])}" if ev.get("official_parser") else "")
        )
    else:
        graders.append("official harness: did not run")
    counts = (
        f"FAIL_TO_PASS {ev['fail_to_pass_passed']}/{ev['fail_to_pass_total']} passed · "
        f"PASS_TO_PASS {ev['pass_to_pass_passed']}/{ev['pass_to_pass_total']} passed · "
        f"evaluated in {ev['duration_s']:.1f} s"
    )
    return (
        f'<section id="evaluation" data-resolved="{str(bool(ev["resolved"])).lower()}" data-reason="{esc(ev["reason"])}">'
        f'<h2>Evaluation <span class="badge {"ok" if ev["resolved"] else "fail"}">{esc(verdict)}</span></h2>'
        f'<p class="graders">{" · ".join(graders)}</p><p class="counts">{counts}</p>'
        f"{tests_html(ev['tests'])}{patch_html(ev['patch'], ev['patch_bytes'])}{log_html(ev['log'], ev['log_bytes'])}"
        "</section>"
    )


def tests_html(raw: str | None) -> str:
    """Each listed test and its status as the deciding grader read the log, failing ones first; the stored
    text as it is when it is not a JSON map."""
    try:
        tests = json.loads(raw or "{}")
    except ValueError:
        tests = None
    if not isinstance(tests, dict):
        return f'<pre class="tests">{esc(raw)}</pre>'
    if not tests:
        return '<p class="tests">No test statuses (the tests did not run).</p>'
    order = sorted(tests.items(), key=lambda kv: (kv[1] in PASSING, kv[0]))
    rows = "".join(
        f'<tr class="{"pass" if status in PASSING else "fail"}" data-test="{esc(t)}"><td><code>{esc(t)}</code></td>'
        f"<td>{esc(status)}</td></tr>"
        for t, status in order
    )
    return f'<table class="data tests" id="eval-tests"><thead><tr><th>test</th><th>status</th></tr></thead><tbody>{rows}</tbody></table>'


def patch_html(patch: str, size: int) -> str:
    """The submitted diff, added lines green and removed ones red (``+++``/``---`` headers plain)."""
    if not patch:
        return '<p class="patch">No diff was submitted.</p>'
    lines = []
    for line in patch.splitlines():
        if line.startswith(("+++", "---")):
            lines.append(f'<span class="same">{esc(line)}</span>')
        elif line.startswith("+"):
            lines.append(f"<ins>{esc(line)}</ins>")
        elif line.startswith("-"):
            lines.append(f"<del>{esc(line)}</del>")
        else:
            lines.append(f'<span class="same">{esc(line)}</span>')
    return (
        f'<details class="patch" open><summary>diff ({num(size)} bytes)</summary><pre class="diff" id="eval-patch">'
        + "\n".join(lines)
        + "</pre></details>"
    )


def log_html(log: str, size: int) -> str:
    """The evaluation's log (the row keeps its tail when it was longer), folded."""
    if not log:
        return '<p class="log">No test log.</p>'
    kept = len(log.encode("utf-8"))
    note = f"{num(size)} bytes" + ("" if kept >= size else f", the last {num(kept)} kept")
    return f'<details class="log"><summary>test log ({note})</summary><pre id="eval-log">{esc(log)}</pre></details>'
