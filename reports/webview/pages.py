"""The viewer's pages as HTML strings: runs, episodes, one episode, a call's window, compare.

Server-rendered on purpose: every page is a plain GET with its state in the URL (filters, sort,
page, search), so a page can be bookmarked, linked from the report and read by a test with
``chromium --dump-dom``; the small script in ``static/app.js`` only adds conveniences (filters
apply on change, a call's window opens in place, expand/collapse the whole tree). Every value
from the tables goes through :func:`html.escape`: messages and observations are model output.
"""

from __future__ import annotations

import difflib
import math
from collections import defaultdict
from html import escape
from typing import Any
from urllib.parse import urlencode

from reports.model import format_value
from reports.observations import observation_change
from reports.stat_notes import mcnemar_note, permutation_note
from reports.viewer import ranges
from reports.webview import data as D

#: discordant pairs listed on the compare page (a run of 10,000 episodes has thousands)
MAX_DISCORDANT = 500
NAV = (("/", "Runs"), ("/episodes", "Episodes"), ("/compare", "Compare"))


def _e(v: Any) -> str:
    return escape("" if v is None else str(v))


def _usd(v: Any) -> str:
    return format_value("usd", v)


def _num(v: Any) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "–"
    if isinstance(v, float):
        return f"{v:,.2f}"
    return f"{v:,}" if isinstance(v, int) and not isinstance(v, bool) else _e(v)


def url(path: str, **params: Any) -> str:
    """``path`` with ``params`` as its query string; None and "" are left out and booleans spelled true/false, so
    a page's state stays a short, bookmarkable URL."""
    clean = {k: ("true" if v is True else "false" if v is False else v) for k, v in params.items() if v not in (None, "")}
    return path + ("?" + urlencode(clean) if clean else "")


def episode_url(run_id: str, episode_id: str, **extra: Any) -> str:
    """The URL of one episode's page (``extra``: e.g. ``hit``, the message to open at)."""
    return url("/episode", run=run_id, id=episode_id, **extra)


def layout(title: str, body: str, *, page: str, snap: D.Snapshot | None = None) -> str:
    """A whole page: head, the navigation (``page`` marks the current entry) and ``body``; with ``snap``, a
    footer saying how fresh the data is and how many part files were skipped."""
    nav = "".join(f'<a href="{h}"{" class=current" if h == page else ""}>{t}</a>' for h, t in NAV)
    foot = ""
    if snap is not None:
        foot = (
            f"<footer>Data as of {_e(_clock(snap.built_at))} (refreshed when part files change) · "
            f"{len(snap.run_dirs)} run folder(s), read-only"
            + (f' · <span class="warn">{len(snap.skipped)} unreadable part file(s) skipped</span>' if snap.skipped else "")
            + "</footer>"
        )
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f'<title>{_e(title)} · recap view</title><link rel="stylesheet" href="/static/app.css">'
        '<script src="/static/app.js" defer></script></head>'
        f'<body data-page="{_e(page.strip("/") or "runs")}"><header><strong>recap view</strong><nav>{nav}</nav></header>'
        f"<main>{body}</main>{foot}</body></html>"
    )


def _clock(ts: float) -> str:
    import time

    return time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(ts))


def error_page(status: int, message: str) -> str:
    """The page for a refused request: the status and its one-line message."""
    return layout(f"Error {status}", f'<h1>Error {status}</h1><p class="error" id="error">{_e(message)}</p>', page="")


# -- runs --------------------------------------------------------------------------------------------


def runs_page(snap: D.Snapshot, runs: list[dict[str, Any]], reports: set[str]) -> str:
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
            f'<tr data-run="{_e(r["run_id"])}"><td>{_e(r["name"])}</td><td><code>{_e(r["run_id"])}</code></td>'
            f'<td><code>{_e(r["run_dir"])}</code></td><td>{_e(r["started"] or "–")}</td><td class="num">{_num(r["starts"])}</td>'
            f'<td class="num">{_num(r["planned"])}</td><td class="num">{_num(r["finished"])}</td><td class="num">{_num(r["not_started"])}</td>'
            f'<td class="num">{_num(r["capped"])}</td><td class="num">{_num(r["gave_up"])}</td>'
            f'<td class="num">{_num(r["successes"])} ({rate})</td>'
            f'<td class="num">{_usd(r["spend_usd"])}</td><td class="num">{_num(r["calls"])}</td><td>{_e(caps)}</td>'
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


def spec_page(snap: D.Snapshot, run_id: str, text: str) -> str:
    """The page showing a run's sweep file (already redacted by :func:`reports.webview.data.run_spec`)."""
    body = (
        f'<h1>Sweep file of <code>{_e(run_id)}</code></h1><p class="note">As recorded at the latest start; values '
        f'under secret-like keys are replaced by &lt;redacted&gt;.</p><pre class="spec">{_e(text)}</pre>'
    )
    return layout("Spec", body, page="/", snap=snap)


# -- episodes ----------------------------------------------------------------------------------------


_HEADERS = (
    ("episode_id", "episode"),
    ("run_id", "run"),
    ("model_label", "model"),
    ("arm", "method"),
    ("label", "label"),
    ("env_split", "split"),
    ("task", "task"),
    ("instance_id", "instance"),
    ("seed", "seed"),
    ("attempt", "attempt"),
    ("end_reason", "end"),
    ("mode", "mode"),
    ("success", "success"),
    ("steps", "steps"),
    ("llm_calls", "calls"),
    ("cost_usd", "cost"),
)


def episodes_page(snap: D.Snapshot, page: D.EpisodePage) -> str:
    """The episode list: filters, message search, sortable headers and page links, all carried in the URL."""
    lq = page.query
    state = {**lq.filters, "q": lq.q, "per": lq.per if lq.per != 50 else None, "latest": "1" if lq.latest else None}
    sort_state = {"sort": lq.sort if lq.sort != "episode_id" else None, "dir": "desc" if lq.desc else None}
    selects = []
    for param, _col in D.FILTERS:
        if param not in snap.options:
            continue
        opts = snap.options[param] if param != "success" else ["true", "false"]
        chosen = lq.filters.get(param, "")
        vals = [str(v).lower() if isinstance(v, bool) else str(v) for v in opts]
        items = "".join(f'<option value="{_e(v)}"{" selected" if v == chosen else ""}>{_e(v)}</option>' for v in vals)
        selects.append(
            f'<label>{_e(param.replace("_", " "))} <select name="{param}" class="filter"><option value="">any</option>{items}</select></label>'
        )
    per = "".join(f"<option{' selected' if n == lq.per else ''}>{n}</option>" for n in D.PAGE_SIZES)
    form = (
        f'<form id="filters" method="get" action="/episodes">{"".join(selects)}'
        f'<label>search messages <input type="search" name="q" id="q" value="{_e(lq.q)}" maxlength="{D.MAX_QUERY_CHARS}" '
        f'placeholder="text in any message"></label>'
        f'<label><input type="checkbox" name="latest" value="1"{" checked" if lq.latest else ""}> latest attempts only</label>'
        f'<label>per page <select name="per">{per}</select></label>'
        + (
            f'<input type="hidden" name="sort" value="{_e(lq.sort)}"><input type="hidden" name="dir" value="{"desc" if lq.desc else "asc"}">'
            if lq.sort != "episode_id" or lq.desc
            else ""
        )
        + '<button type="submit">Apply</button> <a href="/episodes">clear</a></form>'
    )
    cols = [(k, h) for k, h in _HEADERS if k in snap.columns]
    head = []
    for k, h in cols:
        if k in D.SORTABLE:
            desc = lq.sort == k and not lq.desc
            arrow = (" ▼" if lq.desc else " ▲") if lq.sort == k else ""
            head.append(
                f'<th><a class="sort" data-sort="{k}" href="{_e(url("/episodes", **state, sort=k, dir="desc" if desc else None))}">{h}{arrow}</a></th>'
            )
        else:
            head.append(f"<th>{h}</th>")
    if lq.q:
        head.append("<th>hits</th>")
    body_rows = []
    for r in page.rows:
        cells = []
        for k, _ in cols:
            v = r.get(k)
            if k == "episode_id":
                extra = {"hit": r["first_hit"]} if lq.q and r.get("first_hit") is not None else {}
                cells.append(
                    f'<td><a class="ep" href="{_e(episode_url(r["run_id"], str(v), **extra))}">{_e(v)}</a>'
                    + ("" if r.get("is_latest", True) else ' <span class="tag">superseded</span>')
                    + "</td>"
                )
            elif k == "success":
                cells.append(f'<td><span class="badge {"ok" if v else "fail"}">{"yes" if v else "no"}</span></td>')
            elif k == "cost_usd":
                cells.append(f'<td class="num">{_usd(v)}</td>')
            elif isinstance(v, (int, float)) and not isinstance(v, bool):
                cells.append(f'<td class="num">{_num(v)}</td>')
            else:
                cells.append(f"<td>{_e(v if v is not None else '–')}</td>")
        if lq.q:
            cells.append(f'<td class="num">{_num(r["hits"])}</td>')
        body_rows.append(f'<tr data-episode="{_e(r["episode_id"])}" data-run="{_e(r["run_id"])}">{"".join(cells)}</tr>')
    pages = max(1, math.ceil(page.total / lq.per))
    nav = [
        f'<span id="count" data-total="{page.total}" data-ms="{page.elapsed_ms:.1f}">{page.total:,} episode(s)'
        f"{' matching ' + _e(repr(lq.q)) if lq.q else ''} · page {lq.page} of {pages}</span>"
    ]
    if lq.page > 1:
        nav.insert(0, f'<a id="prev" href="{_e(url("/episodes", **state, **sort_state, page=lq.page - 1))}">← previous</a>')
    if lq.page < pages:
        nav.append(f'<a id="next" href="{_e(url("/episodes", **state, **sort_state, page=lq.page + 1))}">next →</a>')
    table = (
        f'<table class="data" id="episodes"><thead><tr>{"".join(head)}</tr></thead><tbody>{"".join(body_rows)}'
        + (f'<tr><td colspan="{len(head)}">no episode matches</td></tr>' if not body_rows else "")
        + "</tbody></table>"
    )
    body = f'<h1>Episodes</h1>{form}<p class="pager">{" · ".join(nav)}</p><div class="scroll">{table}</div>'
    return layout("Episodes", body, page="/episodes", snap=snap)


# -- one episode -------------------------------------------------------------------------------------


def episode_page(snap: D.Snapshot, ep: D.Episode, hit: int | None = None) -> str:
    """One episode: its metadata, context tree, actions with observation changes, LLM calls and messages (opened
    at message ``hit`` when given)."""
    m = ep.meta
    rid, eid = m["run_id"], m["episode_id"]
    meta = [
        ("run", rid),
        ("model", m.get("model_label")),
        ("method", m.get("arm")),
        ("label", m.get("label")),
        ("profile", m.get("profile")),
        ("ablation", m.get("ablation")),
        ("split", m.get("env_split")),
        ("task", m.get("task")),
        ("instance", m.get("instance_id")),
        ("seed", m.get("seed")),
        ("unit", m.get("unit_id")),
        ("attempt", f"{m['attempt']}{'' if m.get('is_latest') else ' (superseded)'}"),
        ("end", m.get("end_reason")),
        ("mode", m.get("mode") or "–"),
        ("steps", m.get("steps")),
        ("step cap", m.get("step_cap")),
        ("LLM calls", m.get("llm_calls")),
        ("prompt tokens", m.get("prompt_tokens")),
        ("cached", m.get("cached_prompt_tokens")),
        ("completion tokens", m.get("completion_tokens")),
        ("cost", _usd(m.get("cost_usd"))),
        ("wall", f"{m.get('wall_s') or 0:.1f} s"),
        ("max depth", m.get("max_depth")),
    ]
    dl = "".join(
        f"<dt>{_e(k)}</dt><dd>{_num(v) if isinstance(v, int) and not isinstance(v, bool) else _e(v)}</dd>"
        for k, v in meta
        if v is not None
    )
    badge = "success" if m["success"] else (m.get("mode") or m["end_reason"])
    parts = [
        f'<h1 id="episode" data-episode="{_e(eid)}" data-run="{_e(rid)}" data-ms="{ep.elapsed_ms:.1f}">{_e(eid)} '
        f'<span class="badge {"ok" if m["success"] else "fail"}">{_e(badge)}</span></h1>',
        f'<dl class="meta">{dl}</dl>',
    ]
    if m.get("error"):
        parts.append(f'<p class="error">{_e(m["error"])}</p>')
    parts.append(
        f'<section id="tree"><h2>Context tree ({len(ep.nodes)} nodes) '
        '<button type="button" id="expand-all">expand all</button> <button type="button" id="collapse-all">collapse all</button></h2>'
        + (tree_html(ep.nodes, ep.steps) if ep.nodes else "<p>No task tree (this method keeps none).</p>")
        + "</section>"
    )
    parts.append(f'<section id="steps"><h2>Actions and observations ({len(ep.steps)})</h2>{steps_html(ep.steps)}</section>')
    parts.append(
        f'<section id="calls"><h2>LLM calls ({len(ep.calls)})</h2>{calls_html(rid, eid, ep.calls)}'
        '<div id="window-panel" class="window-panel" hidden></div></section>'
    )
    parts.append(
        f'<section id="messages"><details{" open" if hit is not None else ""}><summary>Messages ({len(ep.messages)})</summary>'
        f"{messages_html(ep.messages, hit)}</details></section>"
    )
    return layout(f"Episode {eid}", "".join(parts), page="/episode", snap=snap)


def tree_html(nodes: list[dict[str, Any]], steps: list[dict[str, Any]]) -> str:
    """The context tree as nested ``<details>``: each node's versions (think and subtasks, and the call that made
    them) and, for a leaf, the action it ran."""
    ids = {n["node_id"] for n in nodes}
    children: dict[int | None, list[dict[str, Any]]] = defaultdict(list)
    for n in nodes:
        children[n["parent_id"] if n["parent_id"] in ids else None].append(n)
    for v in children.values():
        v.sort(key=lambda n: (n["child_index"], n["node_id"]))
    step_at = {s["index"]: s for s in steps}

    def render(n: dict[str, Any]) -> str:
        versions = []
        for v in n["versions"] or []:
            src = f"call {v['call_index']}" if v["call_index"] is not None else "shortcut"
            think = f'<div class="think">{_e(v["think"])}</div>' if v["think"] else ""
            subs = "".join(f"<li>{_e(s)}</li>" for s in v["subtasks"])
            versions.append(
                f'<li class="version" data-version="{v["version"]}"><span class="tag">v{v["version"]} · {src}</span>'
                f'{think}<ol class="subtasks">{subs}</ol></li>'
            )
        action = ""
        if n["step_index"] is not None and n["step_index"] in step_at:
            s = step_at[n["step_index"]]
            action = (
                f'<p class="action">action <code>{_e(s["action"])}</code> '
                f"{'ok' if s['valid'] else '<span class=invalid>invalid</span>'} (step {s['index']})</p>"
            )
        kids = "".join(render(c) for c in children.get(n["node_id"], []))
        return (
            f'<li><details class="node {_e(n["status"])}" data-node="{n["node_id"]}"{" open" if n["depth"] == 0 else ""}>'
            f'<summary><span class="ntitle">#{n["node_id"]} {_e(n["task"])}</span> <span class="tag">{_e(n["kind"])} · '
            f"{_e(n['status'])} · depth {n['depth']} · {len(n['versions'] or [])} version(s)</span></summary>"
            f'<ol class="versions">{"".join(versions)}</ol>{action}'
            + (f'<ul class="tree">{kids}</ul>' if kids else "")
            + "</details></li>"
        )

    return '<ul class="tree root">' + "".join(render(r) for r in children.get(None, [])) + "</ul>"


def observation_diff(prev: str | None, cur: str) -> str:
    """``cur`` line by line against ``prev``: new lines marked ``<ins>``, dropped ones ``<del>``,
    unchanged ones plain (the first observation is all plain)."""
    if prev is None:
        return _e(cur)
    a, b = prev.splitlines(), cur.splitlines()
    out: list[str] = []
    for op, i1, i2, j1, j2 in difflib.SequenceMatcher(a=a, b=b, autojunk=False).get_opcodes():
        if op == "equal":
            out.extend(f'<span class="same">{_e(x)}</span>' for x in b[j1:j2])
            continue
        out.extend(f"<del>{_e(x)}</del>" for x in a[i1:i2])
        out.extend(f"<ins>{_e(x)}</ins>" for x in b[j1:j2])
    return "\n".join(out)


def steps_html(steps: list[dict[str, Any]]) -> str:
    """The step table: each action, whether it was valid, and what its observation changed (a full diff on request)."""
    if not steps:
        return "<p>No steps.</p>"
    rows, prev = [], None
    for s in steps:
        change = observation_change(prev, s["observation"])
        rows.append(
            f'<tr class="{"" if s["valid"] else "invalid"}" data-step="{s["index"]}"><td>{s["index"]}</td><td>{s["env_step"]}</td>'
            f"<td>{'' if s['node_id'] is None else s['node_id']}</td><td><code>{_e(s['action'])}</code></td>"
            f'<td>{"yes" if s["valid"] else "no"}</td><td class="change">{_e(change)}'
            f'<details><summary>diff</summary><pre class="diff">{observation_diff(prev, s["observation"])}</pre></details></td></tr>'
        )
        prev = s["observation"]
    return (
        '<table class="data"><thead><tr><th>#</th><th>env step</th><th>node</th><th>action</th><th>valid</th>'
        f"<th>observation: what changed since the step before</th></tr></thead><tbody>{''.join(rows)}</tbody></table>"
    )


def calls_html(run_id: str, episode_id: str, calls: list[dict[str, Any]]) -> str:
    """The call table: purpose, status, tokens, cost and the message seqs of each call's window, linked to the window page."""
    if not calls:
        return "<p>No LLM calls.</p>"
    rows = []
    for c in calls:
        status = c["status"] if c["status"] == "ok" else f"{c['status']}: {c['error_kind']}"
        win = ranges(list(c["window_seqs"]))
        href = url("/window", run=run_id, id=episode_id, call=c["call_index"])
        rows.append(
            f'<tr class="{"" if c["status"] == "ok" else "invalid"}" data-call="{c["call_index"]}"><td>{c["call_index"]}</td>'
            f"<td>{_e(c['purpose'])}</td><td>{'' if c['node_id'] is None else c['node_id']}</td><td>{_e(status)}</td>"
            f'<td>{_e(c["model_label"])}</td><td class="num">{c["prompt_tokens"]:,}</td><td class="num">{c["cached_prompt_tokens"]:,}</td>'
            f'<td class="num">{c["completion_tokens"]:,}</td><td class="num">{_usd(c["cost_usd"])}</td>'
            f'<td class="num">{c["latency_s"]:.2f} s</td><td class="num">{c["retries"]}</td><td>{_e(c["error_message"] or "")}</td>'
            f'<td><a class="window" href="{_e(href)}" data-call="{c["call_index"]}">{len(c["window_seqs"])} msgs: {_e(win)}</a></td></tr>'
        )
    return (
        '<table class="data"><thead><tr><th>#</th><th>purpose</th><th>node</th><th>status</th><th>model</th><th>prompt</th>'
        "<th>cached</th><th>completion</th><th>cost</th><th>latency</th><th>retries</th><th>error</th><th>window (message seqs)</th>"
        f"</tr></thead><tbody>{''.join(rows)}</tbody></table>"
    )


def _message_li(m: dict[str, Any], *, hit: bool = False) -> str:
    tag = (
        f"#{m['seq']} {_e(m['role'])} · {_e(m['kind'])}{' · pinned' if m.get('pinned') else ''}"
        f"{'' if m.get('node_id') is None else ' · node ' + str(m['node_id'])}"
    )
    return (
        f'<li class="msg {_e(m["role"])}{" hit" if hit else ""}" id="msg-{m["seq"]}" data-seq="{m["seq"]}">'
        f'<span class="tag">{tag}</span><pre>{_e(m["content"])}</pre></li>'
    )


def messages_html(messages: list[dict[str, Any]], hit: int | None = None) -> str:
    """The messages as a list, the one with seq ``hit`` marked (the search hit the page was opened at)."""
    if not messages:
        return "<p>No messages.</p>"
    return '<ol class="messages">' + "".join(_message_li(m, hit=m["seq"] == hit) for m in messages) + "</ol>"


def window_fragment(run_id: str, episode_id: str, call: dict[str, Any], msgs: list[dict[str, Any]]) -> str:
    """A call's window as an HTML fragment: a summary line, then the messages it was sent in order (seqs missing
    from the messages table shown as such). The episode page loads it in place."""
    seqs = list(call["window_seqs"])
    head = (
        f'<p class="window-head">Window of call {call["call_index"]} ({_e(call["purpose"])}): {len(seqs)} messages '
        f"({_e(ranges(seqs))})"
        + (f"; reply stored as message {call['response_seq']}" if call["response_seq"] is not None else "")
        + f" · {call['prompt_tokens']:,} prompt + {call['completion_tokens']:,} completion tokens, {_usd(call['cost_usd'])}, "
        f"{call['latency_s']:.2f} s, {call['retries']} retries"
        + (f" · error {_e(call['error_kind'])}: {_e(call['error_message'] or '')}" if call["status"] != "ok" else "")
        + "</p>"
    )
    items = []
    for m in msgs:
        if m["role"] is None:
            items.append(f'<li class="msg missing" data-seq="{m["seq"]}">#{m["seq"]} (not in the messages table)</li>')
        else:
            items.append(_message_li(m))
    return (
        f'<div class="window" data-run="{_e(run_id)}" data-episode="{_e(episode_id)}" data-call="{call["call_index"]}">'
        f'{head}<ol class="messages">{"".join(items)}</ol></div>'
    )


def window_page(snap: D.Snapshot, run_id: str, episode_id: str, call: dict[str, Any], msgs: list[dict[str, Any]]) -> str:
    """The stand-alone page of a call's window (the fragment with a link back to its episode)."""
    body = f'<p><a href="{_e(episode_url(run_id, episode_id))}">← episode {_e(episode_id)}</a></p>' + window_fragment(
        run_id, episode_id, call, msgs
    )
    return layout(f"Call {call['call_index']} of {episode_id}", body, page="/window", snap=snap)


# -- compare -----------------------------------------------------------------------------------------


def compare_tests_note(cmp: D.Comparison) -> str:
    """What the comparison's McNemar p and cost p are, from the pairs it made (:mod:`reports.stat_notes`)."""
    pairings = [(cmp.pairs, cmp.instances)] + [(t["pairs"], t["instances"]) for t in cmp.per_task]
    return " ".join(x for x in (mcnemar_note(pairings).replace("p: ", "McNemar p: ", 1), permutation_note([cmp.cost_test])) if x)


def compare_page(snap: D.Snapshot, choices: dict[str, list[str]], cmp: D.Comparison | None, kind: str, a: str, b: str) -> str:
    """The compare page: the two choice forms and, once a comparison ``cmp`` is made, its totals, per-task table
    and discordant pairs (at most MAX_DISCORDANT)."""
    forms = []
    for k, title in (("run", "two runs"), ("arm", "two arms (methods)")):

        def sel(name: str, chosen: str, k: str = k) -> str:
            opts = "".join(f"<option{' selected' if kind == k and v == chosen else ''}>{_e(v)}</option>" for v in choices[k])
            return f'<select name="{name}"><option value="">choose</option>{opts}</select>'

        forms.append(
            f'<form class="compare" id="compare-{k}" method="get" action="/compare"><input type="hidden" name="kind" value="{k}">'
            f'<strong>Compare {title}:</strong> A {sel("a", a)} B {sel("b", b)} <button type="submit">Compare</button></form>'
        )
    body = [
        "<h1>Compare</h1>",
        "".join(forms),
        '<p class="note">Two runs: each unit\'s latest attempt in each run, paired on method, model and instance (task, '
        "instance, seed). Two arms: the terminal rows of the two arms, paired on model, split, task, instance and seed. "
        "Both tests swap A and B within an instance, all its seeds together.</p>",
    ]
    if cmp is not None:
        body.append(f'<p class="note" id="tests">{_e(compare_tests_note(cmp))}</p>')
        body.append(
            f'<section id="result" data-pairs="{cmp.pairs}" data-ms="{cmp.elapsed_ms:.1f}"><h2>{_e(cmp.a)} (A) vs {_e(cmp.b)} (B)</h2>'
            '<table class="data" id="summary"><thead><tr><th>pairs</th><th>A successes</th><th>B successes</th><th>only A</th>'
            "<th>only B</th><th>McNemar p</th><th>mean cost A−B</th><th>cost p</th></tr></thead><tbody>"
            f'<tr><td class="num">{cmp.pairs}</td><td class="num">{cmp.a_successes}</td><td class="num">{cmp.b_successes}</td>'
            f'<td class="num">{cmp.a_only}</td><td class="num">{cmp.b_only}</td><td class="num">{format_value("p", cmp.p_value)}</td>'
            f'<td class="num">{_usd(cmp.mean_cost_diff)}</td><td class="num">{format_value("p", cmp.cost_p)}</td></tr></tbody></table>'
        )
        rows = "".join(
            f'<tr><td>{_e(t["group"])}</td><td>{_e(t["env_split"])}</td><td>{_e(t["task"])}</td><td class="num">{t["pairs"]}</td>'
            f'<td class="num">{t["a_successes"]}</td><td class="num">{t["b_successes"]}</td><td class="num">{t["a_only"]}</td>'
            f'<td class="num">{t["b_only"]}</td><td class="num">{format_value("p", t["p_value"])}</td><td class="num">{_usd(t["mean_cost_diff"])}</td></tr>'
            for t in cmp.per_task
        )
        body.append(
            '<h3>Per task</h3><table class="data" id="per-task"><thead><tr><th>group</th><th>split</th><th>task</th><th>pairs</th>'
            "<th>A ok</th><th>B ok</th><th>only A</th><th>only B</th><th>McNemar p</th><th>mean cost A−B</th></tr></thead>"
            f"<tbody>{rows or '<tr><td colspan=10>no pairs</td></tr>'}</tbody></table>"
        )
        disc = "".join(
            f"<tr><td>{_e(p['grp'])}</td><td>{_e(p['task'])}</td><td>{_e(p['instance_id'])}</td><td>{_e(p['seed'])}</td>"
            f'<td><a class="ep" href="{_e(episode_url(p["a_run"], p["a_episode"]))}">{_e(p["a_episode"])}</a> '
            f'<span class="badge {"ok" if p["a_success"] else "fail"}">{_e(p["a_mode"])}</span></td>'
            f'<td><a class="ep" href="{_e(episode_url(p["b_run"], p["b_episode"]))}">{_e(p["b_episode"])}</a> '
            f'<span class="badge {"ok" if p["b_success"] else "fail"}">{_e(p["b_mode"])}</span></td></tr>'
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
    return layout("Compare", "".join(body), page="/compare", snap=snap)
