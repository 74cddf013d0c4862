"""The runs page (one row per run with its progress, spend and caps) and a run's sweep-file page."""

from __future__ import annotations

from typing import Any

from reports.webview.layout import esc, layout, num, url, usd
from reports.webview.snapshot import Snapshot


def runs_page(snap: Snapshot, runs: list[dict[str, Any]], reports: set[str]) -> str:
    """The runs page: one row per run (success over finished units, caps, spend) with links to its episodes,
    sweep file and report (when ``reports`` holds its folder)."""
    rows = []
    for r in runs:
        rate = f"{100 * r['successes'] / r['finished']:.1f}%" if r.get("finished") else "–"
        caps = ", ".join(f"{k} {v}" for k, v in r["caps"].items()) or "none"
        links = [f'<a href="{url("/episodes", run=r["run_id"])}">episodes</a>']
        if r["has_spec"]:
            links.append(f'<a href="{url("/spec", run=r["run_id"])}">spec</a>')
        if r["run_dir"] in reports:
            links.append(f'<a href="{url("/report", run=r["run_id"])}">report</a>')
        rows.append(
            f'<tr data-run="{esc(r["run_id"])}"><td>{esc(r["name"])}</td><td><code>{esc(r["run_id"])}</code></td>'
            f'<td><code>{esc(r["run_dir"])}</code></td><td>{esc(r["started"] or "–")}</td><td class="num">{num(r["starts"])}</td>'
            f'<td class="num">{num(r["planned"])}</td><td class="num">{num(r["finished"])}</td><td class="num">{num(r["not_started"])}</td>'
            f'<td class="num">{num(r["capped"])}</td><td class="num">{num(r["gave_up"])}</td>'
            f'<td class="num">{num(r["successes"])} ({rate})</td>'
            f'<td class="num">{usd(r["spend_usd"])}</td><td class="num">{num(r["calls"])}</td><td>{esc(caps)}</td>'
            f"<td>{' · '.join(links)}</td></tr>"
        )
    body = (
        '<h1>Runs</h1><table class="data" id="runs"><thead><tr><th>name</th><th>run id</th><th>folder</th><th>started</th>'
        "<th>starts</th><th>units planned</th><th>done</th><th>not started</th><th>capped</th><th>gave up</th><th>successes</th>"
        "<th>spend</th><th>LLM calls</th><th>caps</th><th></th></tr></thead><tbody>" + "".join(rows) + "</tbody></table>"
        '<p class="note">done: units with a final outcome (not budget_exhausted, not an infrastructure failure); '
        "spend: the cost of every recorded call (test doubles are priced nominally).</p>"
    )
    return layout("Runs", body, page="/", snap=snap)


def spec_page(snap: Snapshot, run_id: str, text: str) -> str:
    """The page showing a run's sweep file (already redacted by :func:`reports.webview.runs.run_spec`)."""
    body = (
        f'<h1>Sweep file of <code>{esc(run_id)}</code></h1><p class="note">As recorded at the latest start; values '
        f'under secret-like keys are replaced by &lt;redacted&gt;.</p><pre class="spec">{esc(text)}</pre>'
    )
    return layout("Spec", body, page="/", snap=snap)
