"""What the viewer calls a run and an episode on screen: the run's name (``run:`` in its sweep file, as
run.json records it), not its hex id, and an episode id cut to its first characters (issue 36 item 8:
the episode list fits 1400 px). The full ids stay in the links, ``data-*`` attributes and ``title``s."""

from __future__ import annotations

from pathlib import Path

from reports.webview.runs import _run_name
from reports.webview.snapshot import Snapshot

#: characters of an episode id shown in a table (the id's unit hash starts it; the attempt follows a dash)
SHORT_ID = 8


def run_names(snap: Snapshot) -> dict[str, str]:
    """run_id -> the run's name; a name two runs share gets the first characters of each run's id after it,
    so that no two runs read the same. A run without a folder of its own is named by its id."""
    names: dict[str, str] = {}
    for f in snap.query("SELECT run_dir, run_json_id FROM run_dirs ORDER BY run_dir").dicts():
        if f["run_json_id"]:
            names[f["run_json_id"]] = _run_name(Path(f["run_dir"]))
    for rid in snap.options.get("run", []):
        names.setdefault(str(rid), str(rid))
    taken: dict[str, int] = {}
    for n in names.values():
        taken[n] = taken.get(n, 0) + 1
    return {rid: (f"{n} ({rid[:6]})" if taken[n] > 1 else n) for rid, n in names.items()}


def short_episode(episode_id: str) -> str:
    """An episode id as a table shows it: its first :data:`SHORT_ID` characters and its attempt suffix
    (``077f0da7…-1``); an id that short already, as it is."""
    head, dash, attempt = episode_id.rpartition("-")
    if not dash or not attempt.isdigit():
        head, attempt = episode_id, ""
    if len(head) <= SHORT_ID + 1:
        return episode_id
    return f"{head[:SHORT_ID]}…" + (f"-{attempt}" if attempt else "")
