"""What a run is called on screen: its name (``run:`` in its sweep file, as run.json records it), not its hex
id (issue 36 item 8: run names in every table and drop-down of the viewer, compare page and report)."""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from pathlib import Path

from schemas.parts import read_run_file


def run_names(folders: Iterable[tuple[str, str | None]]) -> dict[str, str]:
    """run_id -> its name (``run`` in run.json, else the folder's name) for each (run folder, run id) pair
    (the ``run_dirs`` table's rows); a name two runs share gets the first characters of each one's id after
    it, so that no two runs read the same."""
    names: dict[str, str] = {}
    for run_dir, rid in folders:
        if rid:
            data = read_run_file(Path(run_dir)) or {}
            names[rid] = str(data.get("run") or data.get("name") or Path(run_dir).name)
    taken = Counter(names.values())
    return {rid: (f"{n} ({rid[:6]})" if taken[n] > 1 else n) for rid, n in names.items()}
