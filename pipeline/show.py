"""``recap show RUN_DIR EPISODE``: one episode's ReCAP context tree in the terminal.

Each node shows its task, kind and status, every (think, subtasks) version it went through, and
for a leaf the action it ran with the outcome. Flat methods (ReAct, Act, ...) have no tree and
are shown as their list of actions. EPISODE is an episode id, a unit id (its latest attempt), or
an unambiguous prefix of either.
"""

from __future__ import annotations

from typing import Any

import pyarrow.compute as pc
from rich.console import Console
from rich.markup import escape
from rich.tree import Tree

from pipeline.errors import PipelineError
from pipeline.store import RunStore
from reports.observations import first_line as _first_line
from reports.observations import observation_change


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


def show_main(run_dir: str, ref: str, console: Console) -> int:
    """``recap show``: print the tree of one episode (and its end reason when it ended in an error); exit status 0."""
    store = RunStore(run_dir)
    store.require_identity()
    ep = resolve_episode(store, ref)
    eid = ep["episode_id"]
    nodes_t, _ = store.read_table("tree_nodes")
    steps_t, _ = store.read_table("steps")
    nodes = nodes_t.filter(pc.equal(nodes_t["episode_id"], eid)).to_pylist() if nodes_t.num_rows else []
    steps = steps_t.filter(pc.equal(steps_t["episode_id"], eid)).to_pylist() if steps_t.num_rows else []
    console.print(build_tree(ep, nodes, steps))
    if ep.get("error"):
        console.print(f"[dim]end: {escape(str(ep['end_reason']))}: {escape(_first_line(ep['error'], 300))}[/dim]")
    return 0
