"""The compare page: the two choice forms and a comparison's totals, per-task table and discordant pairs."""

from __future__ import annotations

from reports.model import format_value
from reports.stat_notes import mcnemar_note, permutation_note
from reports.webview.compare import Comparison
from reports.webview.layout import episode_url, esc, layout, usd
from reports.webview.names import run_names
from reports.webview.snapshot import Snapshot

#: discordant pairs listed on the compare page (a run of 10,000 episodes has thousands)
MAX_DISCORDANT = 500


def compare_tests_note(cmp: Comparison) -> str:
    """What the comparison's McNemar p and cost p are, from the pairs it made (:mod:`reports.stat_notes`)."""
    pairings = [(cmp.pairs, cmp.instances)] + [(t["pairs"], t["instances"]) for t in cmp.per_task]
    return " ".join(x for x in (mcnemar_note(pairings).replace("p: ", "McNemar p: ", 1), permutation_note([cmp.cost_test])) if x)


def compare_page(snap: Snapshot, choices: dict[str, list[str]], cmp: Comparison | None, kind: str, a: str, b: str) -> str:
    """The compare page: the two choice forms and, once a comparison ``cmp`` is made, its totals, per-task table
    and discordant pairs (at most MAX_DISCORDANT)."""
    names = run_names(snap)
    body = ["<h1>Compare</h1>", _forms(choices, kind, a, b, names), _NOTE]
    if cmp is not None:
        body.append(_result(cmp, names if kind == "run" else {}))
    return layout("Compare", "".join(body), page="/compare", snap=snap)


def _forms(choices: dict[str, list[str]], kind: str, a: str, b: str, names: dict[str, str]) -> str:
    """The two choice forms (two runs, by name: ``names``; two arms); the sides chosen are selected in the form
    of ``kind``."""
    forms = []
    for k, title in (("run", "two runs"), ("arm", "two arms (methods)")):

        def sel(name: str, chosen: str, k: str = k) -> str:
            opts = "".join(
                f'<option value="{esc(v)}"{" selected" if kind == k and v == chosen else ""}>'
                f"{esc(names.get(v, v) if k == 'run' else v)}</option>"
                for v in choices[k]
            )
            return f'<select name="{name}"><option value="">choose</option>{opts}</select>'

        forms.append(
            f'<form class="compare" id="compare-{k}" method="get" action="/compare"><input type="hidden" name="kind" value="{k}">'
            f'<strong>Compare {title}:</strong> A {sel("a", a)} B {sel("b", b)} <button type="submit">Compare</button></form>'
        )
    return "".join(forms)


_NOTE = (
    '<p class="note">Two runs: each unit\'s latest attempt in each run, paired on method, model and instance (task, '
    "instance, seed). Two arms: the terminal rows of the two arms, paired on model, split, task, instance and seed. "
    "Both tests swap A and B within an instance, all its seeds together.</p>"
)


def _result(cmp: Comparison, names: dict[str, str]) -> str:
    """A comparison: its tests note, totals, per-task table and discordant pairs (at most MAX_DISCORDANT); the
    sides of a comparison of two runs are named by ``names``."""
    body = []
    body.append(f'<p class="note" id="tests">{esc(compare_tests_note(cmp))}</p>')
    body.append(
        f'<section id="result" data-pairs="{cmp.pairs}" data-ms="{cmp.elapsed_ms:.1f}"><h2>{esc(names.get(cmp.a, cmp.a))} (A) vs {esc(names.get(cmp.b, cmp.b))} (B)</h2>'
        '<table class="data" id="summary"><thead><tr><th>pairs</th><th>A successes</th><th>B successes</th><th>only A</th>'
        "<th>only B</th><th>McNemar p</th><th>mean cost A−B</th><th>cost p</th></tr></thead><tbody>"
        f'<tr><td class="num">{cmp.pairs}</td><td class="num">{cmp.a_successes}</td><td class="num">{cmp.b_successes}</td>'
        f'<td class="num">{cmp.a_only}</td><td class="num">{cmp.b_only}</td><td class="num">{format_value("p", cmp.p_value)}</td>'
        f'<td class="num">{usd(cmp.mean_cost_diff)}</td><td class="num">{format_value("p", cmp.cost_p)}</td></tr></tbody></table>'
    )
    rows = "".join(
        f'<tr><td>{esc(t["group"])}</td><td>{esc(t["env_split"])}</td><td>{esc(t["task"])}</td><td class="num">{t["pairs"]}</td>'
        f'<td class="num">{t["a_successes"]}</td><td class="num">{t["b_successes"]}</td><td class="num">{t["a_only"]}</td>'
        f'<td class="num">{t["b_only"]}</td><td class="num">{format_value("p", t["p_value"])}</td><td class="num">{usd(t["mean_cost_diff"])}</td></tr>'
        for t in cmp.per_task
    )
    body.append(
        '<h3>Per task</h3><table class="data" id="per-task"><thead><tr><th>group</th><th>split</th><th>task</th><th>pairs</th>'
        "<th>A ok</th><th>B ok</th><th>only A</th><th>only B</th><th>McNemar p</th><th>mean cost A−B</th></tr></thead>"
        f"<tbody>{rows or '<tr><td colspan=10>no pairs</td></tr>'}</tbody></table>"
    )
    disc = "".join(
        f"<tr><td>{esc(p['grp'])}</td><td>{esc(p['task'])}</td><td>{esc(p['instance_id'])}</td><td>{esc(p['sampling_seed'])}</td>"
        f'<td><a class="ep" href="{esc(episode_url(p["a_run"], p["a_episode"]))}">{esc(p["a_episode"])}</a> '
        f'<span class="badge {"ok" if p["a_success"] else "fail"}">{esc(p["a_mode"])}</span></td>'
        f'<td><a class="ep" href="{esc(episode_url(p["b_run"], p["b_episode"]))}">{esc(p["b_episode"])}</a> '
        f'<span class="badge {"ok" if p["b_success"] else "fail"}">{esc(p["b_mode"])}</span></td></tr>'
        for p in cmp.discordant[:MAX_DISCORDANT]
    )
    more = (
        f'<p class="note">The first {MAX_DISCORDANT} are listed; filter the episode list by task to see the others.</p>'
        if len(cmp.discordant) > MAX_DISCORDANT
        else ""
    )
    body.append(
        f'<h3>Discordant pairs ({len(cmp.discordant)})</h3>{more}<table class="data" id="discordant"><thead><tr><th>group</th>'
        "<th>task</th><th>instance</th><th>seed</th><th>A episode</th><th>B episode</th></tr></thead>"
        f"<tbody>{disc or '<tr><td colspan=6>none</td></tr>'}</tbody></table></section>"
    )
    return "".join(body)
