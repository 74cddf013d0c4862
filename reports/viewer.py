"""The HTML report's episode viewer: each episode's context tree, actions, observations, calls and windows.

For every node version its think and subtasks; along the tree the actions and observations; every
LLM call and the exact window it saw.

Messages are written once per episode; a call's window is a list of message seqs
(``llm_calls.window_seqs``) that a few lines of JavaScript show on request, so the page grows with
the messages of the shown episodes, not with calls x window. The number of episodes is bounded
(a sample, or the ``--episodes`` the user names) and long texts are cut at a fixed length.
"""

from __future__ import annotations

from collections import defaultdict
from html import escape
from typing import Any

import duckdb

from reports.model import format_value
from reports.views import ReportError, Result, named_query, run_query

#: default number of episodes in the viewer when none are named
DEFAULT_EPISODES = 8
#: characters of one message / observation / think shown before cutting
MAX_MESSAGE_CHARS = 6000
MAX_OBSERVATION_CHARS = 2000


def select_episodes(con: duckdb.DuckDBPyConnection, wanted: list[str] | None, limit: int) -> list[str]:
    """The episode ids to show: ``wanted`` (all must exist) or a sample of ``limit`` covering modes."""
    if wanted:
        found = set(
            run_query(
                con, "SELECT DISTINCT episode_id FROM attempts WHERE list_contains($ids, episode_id)", {"ids": wanted}
            ).column("episode_id")
        )
        missing = [w for w in wanted if w not in found]
        if missing:
            raise ReportError(f"unknown episode id(s) for the viewer: {', '.join(missing)}")
        return list(dict.fromkeys(wanted))
    if limit <= 0:
        return []
    return list(dict.fromkeys(named_query(con, "viewer_sample", {"n": limit}).column("episode_id")))


def _cut(text: str | None, limit: int) -> str:
    if text is None:
        return ""
    if len(text) <= limit:
        return text
    return text[:limit] + f"\n… ({len(text) - limit:,} more characters)"


def ranges(seqs: list[int]) -> str:
    """``[0, 1, 2, 5, 7, 8]`` -> ``"0-2,5,7-8"``."""
    out: list[str] = []
    run: list[int] = []
    for s in sorted(seqs):
        if run and s == run[-1] + 1:
            run.append(s)
            continue
        if run:
            out.append(f"{run[0]}-{run[-1]}" if len(run) > 1 else str(run[0]))
        run = [s]
    if run:
        out.append(f"{run[0]}-{run[-1]}" if len(run) > 1 else str(run[0]))
    return ",".join(out)


def anchor(episode_id: str) -> str:
    """The HTML id of an episode in the viewer: ``ep-`` then the id with every character that is not safe in an
    id spelled as ``_<hex>_`` (ids stay distinct)."""
    return "ep-" + "".join(c if c.isalnum() or c in "-_" else f"_{ord(c):x}_" for c in episode_id)


def build_viewer(con: duckdb.DuckDBPyConnection, ids: list[str], results: dict[str, Result]) -> str:
    """The viewer's HTML for ``ids`` (empty string when there are none)."""
    if not ids:
        return ""
    params = {"ids": ids}
    data = {
        name: named_query(con, name, params)
        for name in ("viewer_episodes", "viewer_nodes", "viewer_steps", "viewer_calls", "viewer_messages")
    }
    results.update({f"{k}": v for k, v in data.items()})
    group: dict[str, dict[tuple[str, str], list[dict[str, Any]]]] = {}
    for name in ("viewer_nodes", "viewer_steps", "viewer_calls", "viewer_messages"):
        g: dict[tuple[str, str], list[dict[str, Any]]] = defaultdict(list)
        for row in data[name].dicts():
            g[(row["run_id"], row["episode_id"])].append(row)
        group[name] = g
    parts = [
        '<section id="viewer" class="viewer"><h2>Episode viewer</h2>',
        f"<p>{len(data['viewer_episodes'].rows)} episode(s). Click a call's window to see the exact "
        "messages it was sent. Long texts are cut.</p>",
    ]
    order = {e: i for i, e in enumerate(ids)}
    for ep in sorted(data["viewer_episodes"].dicts(), key=lambda e: (order.get(e["episode_id"], len(order)), e["run_id"])):
        key = (ep["run_id"], ep["episode_id"])
        parts.append(
            _episode_html(
                ep,
                group["viewer_nodes"][key],
                group["viewer_steps"][key],
                group["viewer_calls"][key],
                group["viewer_messages"][key],
            )
        )
    parts.append("</section>")
    return "\n".join(parts)


def _episode_html(ep: dict[str, Any], nodes: list[dict], steps: list[dict], calls: list[dict], messages: list[dict]) -> str:
    eid = ep["episode_id"]
    aid = anchor(eid)
    meta = [
        ("model", ep["model_label"]),
        ("method", ep["arm"]),
        ("split", ep["env_split"]),
        ("task", ep["task"]),
        ("instance", ep["instance_id"]),
        ("sampling seed", ep["sampling_seed"]),
        ("run", ep["run_id"]),
        ("attempt", f"{ep['attempt']}{'' if ep['is_latest'] else ' (superseded)'}"),
        ("end", ep["end_reason"]),
        ("mode", ep["mode"] or "–"),
        ("steps", ep["steps"]),
        ("calls", ep["llm_calls"]),
        ("cost", format_value("usd", ep["cost_usd"])),
    ]
    out = [
        f'<article class="episode" id="{aid}" data-episode="{escape(eid)}">',
        f'<h3><span class="ep-link" data-episode="{escape(eid)}" data-run="{escape(ep["run_id"])}">{escape(eid)}</span> <span class="badge {"ok" if ep["success"] else "fail"}">{"success" if ep["success"] else escape(ep["mode"] or ep["end_reason"])}</span></h3>',
        '<dl class="meta">' + "".join(f"<dt>{k}</dt><dd>{escape(str(v))}</dd>" for k, v in meta) + "</dl>",
    ]
    if ep["error"]:
        out.append(f'<p class="error">{escape(_cut(ep["error"], 500))}</p>')
    out.append(
        f"<details open><summary>Context tree ({len(nodes)} nodes)</summary>{_tree_html(nodes) if nodes else '<p>No task tree (this method keeps none).</p>'}</details>"
    )
    out.append(f"<details><summary>Actions and observations ({len(steps)})</summary>{_steps_html(steps)}</details>")
    out.append(f"<details><summary>LLM calls ({len(calls)})</summary>{_calls_html(aid, calls)}</details>")
    out.append(f"<details><summary>Messages ({len(messages)})</summary>{_messages_html(aid, messages)}</details>")
    out.append("</article>")
    return "\n".join(out)


def _tree_html(nodes: list[dict]) -> str:
    children: dict[int | None, list[dict]] = defaultdict(list)
    ids = {n["node_id"] for n in nodes}
    for n in nodes:
        parent = n["parent_id"] if n["parent_id"] in ids else None
        children[parent].append(n)
    for v in children.values():
        v.sort(key=lambda n: (n["child_index"], n["node_id"]))

    def render(n: dict) -> str:
        versions = n["versions"] or []
        vs = []
        for v in versions:
            src = f"call {v['call_index']}" if v["call_index"] is not None else "shortcut"
            think = f'<div class="think">{escape(_cut(v["think"], MAX_MESSAGE_CHARS))}</div>' if v["think"] else ""
            subs = "".join(f"<li>{escape(s)}</li>" for s in v["subtasks"])
            vs.append(
                f'<li class="version"><span class="vtag">v{v["version"]} · {src}</span>{think}<ol class="subtasks">{subs}</ol></li>'
            )
        step = f" · step {n['step_index']}" if n["step_index"] is not None else ""
        kids = "".join(render(c) for c in children.get(n["node_id"], []))
        return (
            f'<li class="node {escape(n["status"])}"><span class="ntitle">#{n["node_id"]} {escape(n["task"])}</span> '
            f'<span class="ntag">{escape(n["kind"])} · {escape(n["status"])} · depth {n["depth"]}{step}</span>'
            f'<ol class="versions">{"".join(vs)}</ol>' + (f'<ul class="tree">{kids}</ul>' if kids else "") + "</li>"
        )

    return '<ul class="tree root">' + "".join(render(r) for r in children.get(None, [])) + "</ul>"


def _steps_html(steps: list[dict]) -> str:
    if not steps:
        return "<p>No steps.</p>"
    rows = "".join(
        f'<tr class="{"" if s["valid"] else "invalid"}"><td>{s["index"]}</td><td>{s["env_step"]}</td><td>{"" if s["node_id"] is None else s["node_id"]}</td>'
        f"<td>{escape(s['action'])}</td><td>{'yes' if s['valid'] else 'no'}</td><td><pre>{escape(_cut(s['observation'], MAX_OBSERVATION_CHARS))}</pre></td></tr>"
        for s in steps
    )
    return f'<table class="data"><thead><tr><th>#</th><th>env step</th><th>node</th><th>action</th><th>valid</th><th>observation</th></tr></thead><tbody>{rows}</tbody></table>'


def _calls_html(aid: str, calls: list[dict]) -> str:
    if not calls:
        return "<p>No LLM calls.</p>"
    rows = []
    for c in calls:
        win = ranges(list(c["window_seqs"]))
        status = c["status"] if c["status"] == "ok" else f"{c['status']}: {c['error_kind']}"
        rows.append(
            f'<tr class="{"" if c["status"] == "ok" else "invalid"}"><td>{c["call_index"]}</td><td>{escape(c["purpose"])}</td>'
            f"<td>{'' if c['node_id'] is None else c['node_id']}</td><td>{escape(status)}</td><td>{escape(c['model_label'])}</td>"
            f"<td>{c['prompt_tokens']:,}</td><td>{c['cached_prompt_tokens']:,}</td><td>{c['completion_tokens']:,}</td>"
            f"<td>{format_value('usd', c['cost_usd'])}</td><td>{c['retries']}</td>"
            f'<td><button type="button" class="show-window" id="call-{aid}-{c["call_index"]}" data-target="{aid}" data-seqs="{win}" '
            f'data-response="{"" if c["response_seq"] is None else c["response_seq"]}">{len(c["window_seqs"])} msgs: {win}</button></td></tr>'
        )
    return (
        '<table class="data"><thead><tr><th>#</th><th>purpose</th><th>node</th><th>status</th><th>model</th><th>prompt</th>'
        "<th>cached</th><th>completion</th><th>cost</th><th>retries</th><th>window (message seqs)</th></tr></thead>"
        f'<tbody>{"".join(rows)}</tbody></table><div class="window-panel" id="{aid}-window" hidden></div>'
    )


def _messages_html(aid: str, messages: list[dict]) -> str:
    if not messages:
        return "<p>No messages.</p>"
    items = "".join(
        f'<li class="msg {escape(m["role"])}" data-seq="{m["seq"]}"><span class="mtag">#{m["seq"]} {escape(m["role"])} · {escape(m["kind"])}'
        f"{' · pinned' if m['pinned'] else ''}{'' if m['node_id'] is None else ' · node ' + str(m['node_id'])}</span>"
        f"<pre>{escape(_cut(m['content'], MAX_MESSAGE_CHARS))}</pre></li>"
        for m in messages
    )
    return f'<ol class="messages" id="{aid}-messages">{items}</ol>'
