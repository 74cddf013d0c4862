"""``recap show RUN_DIR EPISODE``: one episode's ReCAP context tree in the terminal.

Each node shows its task, kind and status, every (think, subtasks) version it went through, and
for a leaf the action it ran with the outcome. Flat methods (ReAct, Act, ...) have no tree and
are shown as their list of actions. An episode that called tools (schema version 5) then shows
its tool calls as a transcript: each assistant message's calls (tool and arguments) and each tool
result with what running the call gave (exit code, time, output size, or why it did not run),
under a summary line; a run without a ``tool_calls`` table shows none. EPISODE is an episode id, a
unit id (its latest attempt), or an unambiguous prefix of either.
"""

from __future__ import annotations

from typing import Any

import pyarrow.compute as pc
from rich.console import Console
from rich.markup import escape
from rich.text import Text
from rich.tree import Tree

from pipeline.errors import PipelineError
from pipeline.store import RunStore
from reports.observations import first_line as _first_line
from reports.observations import observation_change
from reports.toolcalls import answered_call, message_calls, one_line, outcome, rows_by_call, totals

#: the ``messages`` columns the tool-call transcript reads (content only for the messages it shows)
_TOOL_MESSAGE_COLUMNS = ["episode_id", "seq", "role", "tool_call_id", "tool_calls"]


def resolve_episode(store: RunStore, ref: str) -> dict[str, Any]:
    """The episode row ``ref`` names: an exact episode id, else a unit id (its latest attempt), else an
    unambiguous prefix (attempts of one unit count as one). Raises PipelineError when none or several match."""
    eps, _ = store.read_table("episodes")
    rows = eps.to_pylist()
    exact = [r for r in rows if r["episode_id"] == ref]
    if exact:
        return exact[0]
    by_unit = [r for r in rows if r["unit_id"] == ref]
    if by_unit:
        return max(by_unit, key=lambda r: r["attempt"])
    pref = [r for r in rows if r["episode_id"].startswith(ref)]
    ids = sorted({r["episode_id"] for r in pref})
    if len(ids) == 1:
        return pref[0]
    if len(ids) > 1:
        units = {r["unit_id"] for r in pref}
        if len(units) == 1:
            return max(pref, key=lambda r: r["attempt"])
        raise PipelineError(f"episode {ref!r} is ambiguous: {', '.join(ids[:5])}{' ...' if len(ids) > 5 else ''}")
    raise PipelineError(f"no episode {ref!r} in {store.location} (use an episode id or unit id from the episodes table)")


def build_tree(episode: dict[str, Any], nodes: list[dict[str, Any]], steps: list[dict[str, Any]]) -> Tree:
    """A rich Tree of one episode: a title line, then the ReCAP nodes with their versions and leaf actions, or
    for a flat method its steps in order; observations shown as changes since the step before."""
    status = "[green]success[/green]" if episode["success"] else f"[red]{episode['end_reason']}[/red]"
    title = (
        f"[bold]{escape(episode['episode_id'])}[/bold]  {escape(episode['instance_id'])}  {escape(episode['method'])} / "
        f"{escape(episode['model'])}  {status}  steps {episode['steps']}  calls {episode['llm_calls']}  ${episode['cost_usd']:.4f}"
    )
    root_tree = Tree(title)
    ordered = sorted(steps, key=lambda s: s["index"])
    step_at = {s["index"]: s for s in ordered}
    # each step's observation shown as what changed since the step before it
    change = {
        s["index"]: observation_change(p["observation"] if p else None, s["observation"])
        for p, s in zip([None, *ordered], ordered)
    }
    if not nodes:
        for s in ordered:
            mark = "[green]ok[/green]" if s["valid"] else "[red]invalid[/red]"
            root_tree.add(f"[cyan]{escape(s['action'])}[/cyan] {mark}  [dim]{escape(change[s['index']])}[/dim]")
        return root_tree
    children: dict[int | None, list[dict[str, Any]]] = {}
    for n in nodes:
        children.setdefault(n["parent_id"], []).append(n)
    for lst in children.values():
        lst.sort(key=lambda n: n["child_index"])

    def add(tree: Tree, node: dict[str, Any]) -> None:
        colour = {"done": "green", "failed": "red", "open": "yellow"}.get(node["status"], "white")
        label = f"[bold]{escape(node['task'])}[/bold]  [dim]{node['kind']}[/dim] [{colour}]{node['status']}[/{colour}]"
        branch = tree.add(label)
        versions = node.get("versions") or []
        show_versions = node["kind"] != "primitive" or any(v.get("think") for v in versions)
        if show_versions:
            for v in versions:
                think = f"think: {_first_line(v.get('think'))} | " if v.get("think") else ""
                subs = ", ".join(v.get("subtasks") or [])
                branch.add(f"[dim]v{v['version']}[/dim] " + escape(f"{think}subtasks: [{subs}]"))
        if node.get("step_index") is not None and node["step_index"] in step_at:
            s = step_at[node["step_index"]]
            mark = "[green]ok[/green]" if s["valid"] else "[red]invalid[/red]"
            branch.add(f"action [cyan]{escape(s['action'])}[/cyan] {mark}  [dim]{escape(change[s['index']])}[/dim]")
        for child in children.get(node["node_id"], []):
            add(branch, child)

    for top in children.get(None, []):
        add(root_tree, top)
    return root_tree


def tool_call_lines(
    rows: list[dict[str, Any]], messages: list[dict[str, Any]], steps: list[dict[str, Any]] | None = None
) -> list[Text]:
    """An episode's tool calls as lines: the summary, then in message order each assistant message's
    calls (``#seq assistant call NAME ARGUMENTS [id]``, its text first when it wrote any) and each tool
    result (``#seq tool [id] (OUTCOME) first line``), then calls no message made (commands written as
    text: ``step N command NAME ARGUMENTS: OUTCOME``). [] when the episode made none. Every model-written
    string is plain text (never markup) on one line.

    A tool result's first line is its output's: the observation of the call's step (``steps``) when the
    episode has it, since a method may wrap the output in a prompt (ReCAP's tool message opens with
    ``Latest observation:``, recap/recap_tool_prompts.py ``action_taken_prompt``); else the message's."""
    observation = {s["index"]: s["observation"] for s in steps or []}
    rows = sorted(rows, key=lambda r: r["index"])
    msgs = sorted(
        (m for m in messages if m.get("tool_calls") is not None or m.get("tool_call_id") is not None), key=lambda m: m["seq"]
    )
    if not rows and not msgs:
        return []
    by_call = rows_by_call(rows)
    answers = answered_call(msgs)
    out = [Text(totals(rows).line(), style="bold")]
    for m in msgs:
        seq = m["seq"]
        calls = message_calls(m.get("tool_calls"))
        if m.get("tool_call_id") is None:
            if (m.get("content") or "").strip():
                out.append(Text(f"  #{seq} {m['role']}: {one_line(_first_line(m['content']))}"))
            if calls is None:
                out.append(Text(f"  #{seq} {m['role']} calls (unreadable): {one_line(m['tool_calls'])}", style="red"))
            for c in calls or []:
                out.append(
                    Text.assemble(
                        f"  #{seq} {m['role']} call ", (one_line(c.name), "cyan"), f" {one_line(c.arguments)} [{one_line(c.id)}]"
                    )
                )
            continue
        cid = m["tool_call_id"]
        row = by_call.get((answers.get(seq), cid))
        result = outcome(row) if row is not None else "not recorded"
        bad = row is None or not row["valid"] or row["timed_out"]
        shown = m.get("content")
        if row is not None and row.get("step_index") in observation:
            shown = observation[row["step_index"]]
        out.append(
            Text.assemble(
                f"  #{seq} {m['role']} [{one_line(cid)}] (",
                (one_line(result), "red" if bad else "green"),
                f") {one_line(_first_line(shown))}",
            )
        )
    for r in rows:
        if r["call_id"] is None:
            out.append(
                Text.assemble(
                    f"  step {r['step_index']} command ",
                    (one_line(r["name"]), "cyan"),
                    f" {one_line(r['arguments'])}: ",
                    (one_line(outcome(r)), "red" if not r["valid"] or r["timed_out"] else "green"),
                )
            )
    return out


def _episode_rows(store: RunStore, table: str, eid: str, columns: list[str] | None = None) -> list[dict[str, Any]]:
    """The rows of one episode in ``table`` ([] when the run has none: a table it never wrote)."""
    data, _ = store.read_table(table, columns)
    return data.filter(pc.equal(data["episode_id"], eid)).to_pylist() if data.num_rows else []


def _tool_messages(store: RunStore, eid: str) -> list[dict[str, Any]]:
    """The episode's messages that make or answer tool calls, with their content (read only for them)."""
    tool = [
        m
        for m in _episode_rows(store, "messages", eid, _TOOL_MESSAGE_COLUMNS)
        if m["tool_calls"] is not None or m["tool_call_id"] is not None
    ]
    if not tool:
        return []
    seqs = {m["seq"] for m in tool}
    return [m for m in _episode_rows(store, "messages", eid, [*_TOOL_MESSAGE_COLUMNS, "content"]) if m["seq"] in seqs]


def show_main(run_dir: str, ref: str, console: Console) -> int:
    """``recap show``: print the tree of one episode, its tool calls (:func:`tool_call_lines`), and its end reason
    when it ended in an error; exit status 0."""
    store = RunStore(run_dir)
    store.require_identity()
    ep = resolve_episode(store, ref)
    eid = ep["episode_id"]
    nodes_t, _ = store.read_table("tree_nodes")
    steps_t, _ = store.read_table("steps")
    nodes = nodes_t.filter(pc.equal(nodes_t["episode_id"], eid)).to_pylist() if nodes_t.num_rows else []
    steps = steps_t.filter(pc.equal(steps_t["episode_id"], eid)).to_pylist() if steps_t.num_rows else []
    console.print(build_tree(ep, nodes, steps))
    for line in tool_call_lines(_episode_rows(store, "tool_calls", eid), _tool_messages(store, eid), steps):
        console.print(line)
    if ep.get("error"):
        console.print(f"[dim]end: {escape(str(ep['end_reason']))}: {escape(_first_line(ep['error'], 300))}[/dim]")
    return 0
