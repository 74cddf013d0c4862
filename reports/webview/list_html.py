"""The episode list page: filters, message search, sortable headers and page links, all carried in the URL."""

from __future__ import annotations

import math
from typing import Any

from reports.webview.episodes import EpisodePage
from reports.webview.layout import episode_url, esc, layout, num, url, usd
from reports.webview.listquery import MAX_QUERY_CHARS, PAGE_SIZES, SORTABLE, ListQuery
from reports.webview.names import run_names, short_episode
from reports.webview.snapshot import FILTERS, Snapshot

#: the list's columns, the outcome first (issue 36 item 8: at 1400 px a researcher sees what happened before
#: which episode it was). Split and task are not columns: the instance id repeats them (both stay filters);
#: nor is the arm's label, which the method column shows (``arm`` is the label).
_HEADERS = (
    ("success", "success"),
    ("end_reason", "end"),
    ("mode", "mode"),
    ("steps", "steps"),
    ("llm_calls", "calls"),
    ("cost_usd", "cost"),
    ("episode_id", "episode"),
    ("run_id", "run"),
    ("model_label", "model"),
    ("arm", "method"),
    ("instance_id", "instance"),
    ("sampling_seed", "seed"),
    ("attempt", "attempt"),
)


def _filter_form(snap: Snapshot, lq: ListQuery, names: dict[str, str]) -> str:
    """The filter form: one select per filter the runs have (a run by its name, ``names``), the message search,
    latest-only and the page size (the sort carried in hidden fields)."""
    selects = []
    for param, _col in FILTERS:
        if param not in snap.options:
            continue
        opts = snap.options[param] if param != "success" else ["true", "false"]
        chosen = lq.filters.get(param, "")
        vals = [str(v).lower() if isinstance(v, bool) else str(v) for v in opts]
        shown = (lambda v: names.get(v, v)) if param == "run" else (lambda v: v)
        items = "".join(f'<option value="{esc(v)}"{" selected" if v == chosen else ""}>{esc(shown(v))}</option>' for v in vals)
        selects.append(
            f'<label>{esc(param.replace("_", " "))} <select name="{param}" class="filter"><option value="">any</option>{items}</select></label>'
        )
    per = "".join(f"<option{' selected' if n == lq.per else ''}>{n}</option>" for n in PAGE_SIZES)
    return (
        f'<form id="filters" method="get" action="/episodes">{"".join(selects)}'
        f'<label>search messages <input type="search" name="q" id="q" value="{esc(lq.q)}" maxlength="{MAX_QUERY_CHARS}" '
        f'placeholder="text in any message"></label>'
        f'<label><input type="checkbox" name="latest" value="1"{" checked" if lq.latest else ""}> latest attempts only</label>'
        f'<label>per page <select name="per">{per}</select></label>'
        + (
            f'<input type="hidden" name="sort" value="{esc(lq.sort)}"><input type="hidden" name="dir" value="{"desc" if lq.desc else "asc"}">'
            if lq.sort != "episode_id" or lq.desc
            else ""
        )
        + '<button type="submit">Apply</button> <a href="/episodes">clear</a></form>'
    )


def _head(cols: list[tuple[str, str]], lq: ListQuery, state: dict[str, Any]) -> list[str]:
    """The header cells: a sortable column links to the list sorted by it (a second click reverses)."""
    head = []
    for k, h in cols:
        if k in SORTABLE:
            desc = lq.sort == k and not lq.desc
            arrow = (" ▼" if lq.desc else " ▲") if lq.sort == k else ""
            head.append(
                f'<th><a class="sort" data-sort="{k}" href="{esc(url("/episodes", **state, sort=k, dir="desc" if desc else None))}">{h}{arrow}</a></th>'
            )
        else:
            head.append(f"<th>{h}</th>")
    if lq.q:
        head.append("<th>hits</th>")
    return head


def _cell(k: str, r: dict[str, Any], lq: ListQuery, names: dict[str, str]) -> str:
    """One cell of an episode row: the id (shortened, whole in its title) links to the episode (at its first
    search hit), the run is its name, success is a badge."""
    v = r.get(k)
    if k == "episode_id":
        extra = {"hit": r["first_hit"]} if lq.q and r.get("first_hit") is not None else {}
        return (
            f'<td class="id"><a class="ep" href="{esc(episode_url(r["run_id"], str(v), **extra))}" '
            f'data-episode="{esc(v)}" title="{esc(v)}">{esc(short_episode(str(v)))}</a>'
            + ("" if r.get("is_latest", True) else ' <span class="tag">superseded</span>')
            + "</td>"
        )
    if k == "run_id":
        return f'<td title="{esc(v)}">{esc(names.get(str(v), v))}</td>'
    if k == "success":
        return f'<td><span class="badge {"ok" if v else "fail"}">{"yes" if v else "no"}</span></td>'
    if k == "cost_usd":
        return f'<td class="num">{usd(v)}</td>'
    if k == "instance_id":
        return f'<td class="long">{esc(v if v is not None else "–")}</td>'
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return f'<td class="num">{num(v)}</td>'
    return f"<td>{esc(v if v is not None else '–')}</td>"


def _pager(page: EpisodePage, state: dict[str, Any], sort_state: dict[str, Any]) -> list[str]:
    """The count of matching episodes and the previous / next page links."""
    lq = page.query
    pages = max(1, math.ceil(page.total / lq.per))
    nav = [
        f'<span id="count" data-total="{page.total}" data-ms="{page.elapsed_ms:.1f}">{page.total:,} episode(s)'
        f"{' matching ' + esc(repr(lq.q)) if lq.q else ''} · page {lq.page} of {pages}</span>"
    ]
    if lq.page > 1:
        nav.insert(0, f'<a id="prev" href="{esc(url("/episodes", **state, **sort_state, page=lq.page - 1))}">← previous</a>')
    if lq.page < pages:
        nav.append(f'<a id="next" href="{esc(url("/episodes", **state, **sort_state, page=lq.page + 1))}">next →</a>')
    return nav


def episodes_page(snap: Snapshot, page: EpisodePage) -> str:
    """The episode list: filters, message search, sortable headers and page links, all carried in the URL."""
    lq = page.query
    state = {**lq.filters, "q": lq.q, "per": lq.per if lq.per != 50 else None, "latest": "1" if lq.latest else None}
    sort_state = {"sort": lq.sort if lq.sort != "episode_id" else None, "dir": "desc" if lq.desc else None}
    names = run_names(snap)
    form = _filter_form(snap, lq, names)
    cols = [(k, h) for k, h in _HEADERS if k in snap.columns]
    head = _head(cols, lq, state)
    body_rows = []
    for r in page.rows:
        cells = [_cell(k, r, lq, names) for k, _ in cols]
        if lq.q:
            cells.append(f'<td class="num">{num(r["hits"])}</td>')
        body_rows.append(f'<tr data-episode="{esc(r["episode_id"])}" data-run="{esc(r["run_id"])}">{"".join(cells)}</tr>')
    nav = _pager(page, state, sort_state)
    table = (
        f'<table class="data" id="episodes"><thead><tr>{"".join(head)}</tr></thead><tbody>{"".join(body_rows)}'
        + (f'<tr><td colspan="{len(head)}">no episode matches</td></tr>' if not body_rows else "")
        + "</tbody></table>"
    )
    body = f'<h1>Episodes</h1>{form}<p class="pager">{" · ".join(nav)}</p><div class="scroll">{table}</div>'
    return layout("Episodes", body, page="/episodes", snap=snap)
