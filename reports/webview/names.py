"""What the viewer calls a run and an episode on screen: the run's name, not its hex id, and an episode id
cut to its first characters (issue 36 item 8: the episode list fits 1400 px). The full ids stay in the links, ``data-*`` attributes and ``title``s."""

from __future__ import annotations

from reports.run_names import run_names as name_runs
from reports.webview.snapshot import Snapshot

#: characters of an episode id shown in a table (the id's unit hash starts it; the attempt follows a dash)
SHORT_ID = 8


def run_names(snap: Snapshot) -> dict[str, str]:
    """run_id -> the run's name (:func:`reports.run_names.run_names`); a run without a folder of its own
    (run.json) is named by its id."""
    names = name_runs(snap.query("SELECT run_dir, run_json_id FROM run_dirs ORDER BY run_dir").rows)
    for rid in snap.options.get("run", []):
        names.setdefault(str(rid), str(rid))
    return names


def short_episode(episode_id: str) -> str:
    """An episode id as a table shows it: its first :data:`SHORT_ID` characters and its attempt suffix
    (``077f0da7…-1``); an id that short already, as it is."""
    head, dash, attempt = episode_id.rpartition("-")
    if not dash or not attempt.isdigit():
        head, attempt = episode_id, ""
    if len(head) <= SHORT_ID + 1:
        return episode_id
    return f"{head[:SHORT_ID]}…" + (f"-{attempt}" if attempt else "")
