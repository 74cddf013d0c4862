"""One episode's page: its metadata, context tree, actions with observation changes, calls, messages and windows."""

from __future__ import annotations

import difflib
from collections import defaultdict
from typing import Any

from reports.observations import observation_change
from reports.toolcalls import message_calls, totals
from reports.viewer import ranges
from reports.webview.episodes import Episode
from reports.webview.evaluation_html import evaluation_html
from reports.webview.layout import episode_url, esc, layout, num, url, usd
from reports.webview.snapshot import Snapshot


def episode_page(snap: Snapshot, ep: Episode, hit: int | None = None) -> str:
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
        ("sampling seed", m.get("sampling_seed")),
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
        ("cost", usd(m.get("cost_usd"))),
        ("wall", f"{m.get('wall_s') or 0:.1f} s"),
        ("max depth", m.get("max_depth")),
    ]
    dl = "".join(
        f"<dt>{esc(k)}</dt><dd>{num(v) if isinstance(v, int) and not isinstance(v, bool) else esc(v)}</dd>"
        for k, v in meta
        if v is not None
    )
    badge = "success" if m["success"] else (m.get("mode") or m["end_reason"])
    parts = [
        f'<h1 id="episode" data-episode="{esc(eid)}" data-run="{esc(rid)}" data-ms="{ep.elapsed_ms:.1f}">{esc(eid)} '
        f'<span class="badge {"ok" if m["success"] else "fail"}">{esc(badge)}</span></h1>',
        f'<dl class="meta">{dl}</dl>',
    ]
    if m.get("error"):
        parts.append(f'<p class="error">{esc(m["error"])}</p>')
    parts.extend(evaluation_html(ev) for ev in ep.evaluations)  # a coding episode's verdict, before its tree
    parts.append(
        f'<section id="tree"><h2>Context tree ({len(ep.nodes)} nodes) '
        '<button type="button" id="expand-all">expand all</button> <button type="button" id="collapse-all">collapse all</button></h2>'
        + (tree_html(ep.nodes, ep.steps, ep.calls) if ep.nodes else "<p>No task tree (this method keeps none).</p>")
        + "</section>"
    )
    parts.append(f'<section id="steps"><h2>Actions and observations ({len(ep.steps)})</h2>{steps_html(ep.steps)}</section>')
    if ep.tool_calls:  # an episode without tool calls (every run before schema version 5) shows no such section
        parts.append(
            f'<section id="tool-calls"><h2>Tool calls ({len(ep.tool_calls)})</h2>'
            f'<p class="tool-summary">{esc(totals(ep.tool_calls).line())}</p>{tool_calls_html(ep.tool_calls)}</section>'
        )
    parts.append(
        f'<section id="calls"><h2>LLM calls ({len(ep.calls)})</h2>{calls_html(rid, eid, ep.calls)}'
        '<div id="window-panel" class="window-panel" hidden></div></section>'
    )
    parts.append(
        f'<section id="messages"><details{" open" if hit is not None else ""}><summary>Messages ({len(ep.messages)})</summary>'
        f"{messages_html(ep.messages, hit)}</details></section>"
    )
    return layout(f"Episode {eid}", "".join(parts), page="/episode", snap=snap)


def tree_html(nodes: list[dict[str, Any]], steps: list[dict[str, Any]], calls: list[dict[str, Any]] | None = None) -> str:
    """The context tree as nested ``<details>``, each node read top down on one screen (issue 36 item 9): its
    summary line (a leaf's action, whether it was valid and what its observation changed, on that line), its
    latest version (think and subtasks, one line each, and the call that made it), then its children; the
    node's timeline (call -> version -> action -> observation, in order) folded below the latest version, so
    that a root refined 29 times shows one version, not 29, before its first child."""
    ids = {n["node_id"] for n in nodes}
    children: dict[int | None, list[dict[str, Any]]] = defaultdict(list)
    for n in nodes:
        children[n["parent_id"] if n["parent_id"] in ids else None].append(n)
    for v in children.values():
        v.sort(key=lambda n: (n["child_index"], n["node_id"]))
    step_at = {s["index"]: s for s in steps}
    change_at, prev = {}, None
    for s in steps:
        change_at[s["index"]] = observation_change(prev, s["observation"])
        prev = s["observation"]
    purpose = {c["call_index"]: c["purpose"] for c in calls or []}

    def made_by(v: dict[str, Any]) -> str:
        if v["call_index"] is None:
            return "shortcut"
        p = purpose.get(v["call_index"])
        return f"call {v['call_index']}" + (f" ({p})" if p else "")

    def version_li(v: dict[str, Any], cls: str) -> str:
        think = f'<div class="think">{esc(v["think"])}</div>' if v["think"] else ""
        subs = "".join(f'<li title="{esc(s)}">{esc(s)}</li>' for s in v["subtasks"])
        return (
            f'<li class="{cls}" data-version="{v["version"]}"><span class="tag">{made_by(v)} → v{v["version"]}</span>'
            f'{think}<ol class="subtasks">{subs}</ol></li>'
        )

    def action_html(n: dict[str, Any]) -> str:
        if n["step_index"] is None or n["step_index"] not in step_at:
            return ""
        s = step_at[n["step_index"]]
        return (
            f'<span class="action">→ step {s["index"]} '
            + ("" if s["action"] == n["task"] else f"<code>{esc(s['action'])}</code> ")
            + f"{'ok' if s['valid'] else '<span class=invalid>invalid</span>'} → "
            f'<span class="obs">{esc(change_at.get(s["index"], ""))}</span></span>'
        )

    def render(n: dict[str, Any]) -> str:
        versions = list(n["versions"] or [])
        latest = version_li(versions[-1], "version latest") if versions else ""
        leaf_shortcut = len(versions) == 1 and versions[0]["call_index"] is None and versions[0]["subtasks"] == [n["task"]]
        history = ""
        if len(versions) > 1:
            calls_made = [v["call_index"] for v in versions if v["call_index"] is not None]
            span = f", calls {calls_made[0]}–{calls_made[-1]}" if len(calls_made) > 1 else ""
            history = (
                f'<details class="history"><summary>timeline: {len(versions)} versions{span}</summary>'
                f'<ol class="versions">{"".join(version_li(v, "version") for v in versions)}</ol></details>'
            )
        kids = "".join(render(c) for c in children.get(n["node_id"], []))
        return (
            f'<li><details class="node {esc(n["status"])}" data-node="{n["node_id"]}"{" open" if n["depth"] == 0 else ""}>'
            f'<summary><span class="ntitle" title="{esc(n["task"])}">#{n["node_id"]} {esc(n["task"])}</span> '
            f'<span class="tag">{esc(n["kind"])} · {esc(n["status"])} · depth {n["depth"]} · {len(versions)} version(s)</span>'
            f"{action_html(n)}</summary>"
            + ("" if leaf_shortcut else f'<ol class="versions latest">{latest}</ol>')
            + history
            + (f'<ul class="tree">{kids}</ul>' if kids else "")
            + "</details></li>"
        )

    return '<ul class="tree root">' + "".join(render(r) for r in children.get(None, [])) + "</ul>"


def observation_diff(prev: str | None, cur: str) -> str:
    """``cur`` line by line against ``prev``: new lines marked ``<ins>``, dropped ones ``<del>``,
    unchanged ones plain (the first observation is all plain)."""
    if prev is None:
        return esc(cur)
    a, b = prev.splitlines(), cur.splitlines()
    out: list[str] = []
    for op, i1, i2, j1, j2 in difflib.SequenceMatcher(a=a, b=b, autojunk=False).get_opcodes():
        if op == "equal":
            out.extend(f'<span class="same">{esc(x)}</span>' for x in b[j1:j2])
            continue
        out.extend(f"<del>{esc(x)}</del>" for x in a[i1:i2])
        out.extend(f"<ins>{esc(x)}</ins>" for x in b[j1:j2])
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
            f"<td>{'' if s['node_id'] is None else s['node_id']}</td><td><code>{esc(s['action'])}</code></td>"
            f'<td>{"yes" if s["valid"] else "no"}</td><td class="change">{esc(change)}'
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
            f"<td>{esc(c['purpose'])}</td><td>{'' if c['node_id'] is None else c['node_id']}</td><td>{esc(status)}</td>"
            f'<td>{esc(c["model_label"])}</td><td class="num">{c["prompt_tokens"]:,}</td><td class="num">{c["cached_prompt_tokens"]:,}</td>'
            f'<td class="num">{c["completion_tokens"]:,}</td><td class="num">{usd(c["cost_usd"])}</td>'
            f'<td class="num">{c["latency_s"]:.2f} s</td><td class="num">{c["retries"]}</td><td>{esc(c["error_message"] or "")}</td>'
            f'<td><a class="window" href="{esc(href)}" data-call="{c["call_index"]}">{len(c["window_seqs"])} msgs: {esc(win)}</a></td></tr>'
        )
    return (
        '<table class="data"><thead><tr><th>#</th><th>purpose</th><th>node</th><th>status</th><th>model</th><th>prompt</th>'
        "<th>cached</th><th>completion</th><th>cost</th><th>latency</th><th>retries</th><th>error</th><th>window (message seqs)</th>"
        f"</tr></thead><tbody>{''.join(rows)}</tbody></table>"
    )


def tool_calls_html(rows: list[dict[str, Any]]) -> str:
    """The tool call table: each call in order with its tool, arguments (as the model wrote them), exit
    code, duration, output size and error; its message links to the assistant message that made it."""
    out = []
    for r in rows:
        seq = r["message_seq"]
        msg = "" if seq is None else f'<a href="#msg-{seq}">#{seq}</a>'
        out.append(
            f'<tr class="{"" if r["valid"] and not r["timed_out"] else "invalid"}" data-tool-call="{r["index"]}">'
            f"<td>{r['index']}</td><td>{r['step_index']}</td><td>{msg}</td><td>{esc(r['call_id'])}</td>"
            f"<td><code>{esc(r['name'])}</code></td><td><code>{esc(r['arguments'])}</code></td>"
            f"<td>{'yes' if r['valid'] else 'no'}</td><td>{'' if r['exit_code'] is None else r['exit_code']}</td>"
            f'<td class="num">{r["duration_s"]:.2f} s</td><td class="num">{r["output_bytes"]:,}</td>'
            f"<td>{'yes' if r['timed_out'] else ''}</td><td>{esc(r['error'])}</td></tr>"
        )
    return (
        '<table class="data"><thead><tr><th>#</th><th>step</th><th>message</th><th>call id</th><th>tool</th>'
        "<th>arguments</th><th>valid</th><th>exit code</th><th>duration</th><th>output bytes</th><th>timed out</th>"
        f"<th>error</th></tr></thead><tbody>{''.join(out)}</tbody></table>"
    )


def _message_calls_html(raw: str | None) -> str:
    """An assistant message's tool calls (name, arguments, call id) under its text; the stored text as it is
    when it is not the runtime's JSON."""
    calls = message_calls(raw)
    if calls is None:
        return f'<pre class="tool-calls">{esc(raw)}</pre>'
    items = "".join(
        f'<li data-call-id="{esc(c.id)}">call <code>{esc(c.name)}</code> <code>{esc(c.arguments)}</code> '
        f'<span class="tag">id {esc(c.id)}</span></li>'
        for c in calls
    )
    return f'<ol class="tool-calls">{items}</ol>' if items else ""


def _message_li(m: dict[str, Any], *, hit: bool = False) -> str:
    answers = m.get("tool_call_id")
    tag = (
        f"#{m['seq']} {esc(m['role'])} · {esc(m['kind'])}{' · pinned' if m.get('pinned') else ''}"
        f"{'' if m.get('node_id') is None else ' · node ' + str(m['node_id'])}"
        f"{'' if answers is None else ' · answers call ' + esc(answers)}"
    )
    calls = _message_calls_html(m.get("tool_calls"))
    text = "" if calls and not m["content"] else f"<pre>{esc(m['content'])}</pre>"
    return (
        f'<li class="msg {esc(m["role"])}{" hit" if hit else ""}" id="msg-{m["seq"]}" data-seq="{m["seq"]}">'
        f'<span class="tag">{tag}</span>{text}{calls}</li>'
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
        f'<p class="window-head">Window of call {call["call_index"]} ({esc(call["purpose"])}): {len(seqs)} messages '
        f"({esc(ranges(seqs))})"
        + (f"; reply stored as message {call['response_seq']}" if call["response_seq"] is not None else "")
        + f" · {call['prompt_tokens']:,} prompt + {call['completion_tokens']:,} completion tokens, {usd(call['cost_usd'])}, "
        f"{call['latency_s']:.2f} s, {call['retries']} retries"
        + (f" · error {esc(call['error_kind'])}: {esc(call['error_message'] or '')}" if call["status"] != "ok" else "")
        + "</p>"
    )
    items = []
    for m in msgs:
        if m["role"] is None:
            items.append(f'<li class="msg missing" data-seq="{m["seq"]}">#{m["seq"]} (not in the messages table)</li>')
        else:
            items.append(_message_li(m))
    return (
        f'<div class="window" data-run="{esc(run_id)}" data-episode="{esc(episode_id)}" data-call="{call["call_index"]}">'
        f'{head}<ol class="messages">{"".join(items)}</ol></div>'
    )


def window_page(snap: Snapshot, run_id: str, episode_id: str, call: dict[str, Any], msgs: list[dict[str, Any]]) -> str:
    """The stand-alone page of a call's window (the fragment with a link back to its episode)."""
    body = f'<p><a href="{esc(episode_url(run_id, episode_id))}">← episode {esc(episode_id)}</a></p>' + window_fragment(
        run_id, episode_id, call, msgs
    )
    return layout(f"Call {call['call_index']} of {episode_id}", body, page="/window", snap=snap)
