"""The ALFWorld data folders as ``recap data`` sees them: the primary folder (game files 2.1.1)
and the optional 2.1.2 one, their release archives, and the 2.1.2 folder's own search rule
(see pipeline/data.py for the command and why ALFWorld's own downloader is not called).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from workers.envs import data_paths
from workers.envs.data_sources import DataFolder, Group, Source

from .games import DATA_ENV_2_1_2, LOCATION, SIBLING_2_1_2, SPLIT_DIR

#: ALFWorld release assets (the URLs of alfworld-download; 2.1.1 games: ALFWorld 0.3.x's, 2.1.2: 0.4.2's)
RELEASES = "https://github.com/alfworld/alfworld/releases/download"
JSON_URL = f"{RELEASES}/0.2.2/json_2.1.1_json.zip"
PDDL_URL = f"{RELEASES}/0.2.2/json_2.1.1_pddl.zip"
TW_PDDL_2_1_1_URL = f"{RELEASES}/0.2.2/json_2.1.1_tw-pddl.zip"
TW_PDDL_2_1_2_URL = f"{RELEASES}/0.4.0/json_2.1.2_tw-pddl.zip"
#: alfworld 0.3.5's package data: the PDDL domain and grammar in 2.1.1 wording (the manifest's logic/)
LOGIC_BASE = "https://raw.githubusercontent.com/alfworld/alfworld/0.3.5/alfworld/data"

_VALID_UNSEEN = re.compile(r"(?:^|/)(valid_unseen/.+)$")


def member_path(member: str) -> str | None:
    """Any ``.../valid_unseen/<game>/<trial>/<file>`` member -> ``json_2.1.1/valid_unseen/...``."""
    match = _VALID_UNSEEN.search(member)
    return f"json_2.1.1/{match.group(1)}" if match else None


#: the optional 2.1.2 folder (same games, 2.1.2 wording, walkthroughs), found by its own rule
LOCATION_2_1_2 = data_paths.DataLocation(
    name="alfworld-2.1.2", title="ALFWorld (game files 2.1.2)", env_var=DATA_ENV_2_1_2, marker=LOCATION.marker
)


def search_2_1_2(data_dir: str | None) -> tuple[list[data_paths.Rung], data_paths.Rung | None]:
    """The 2.1.2 rule (games.resolve_data_dir_2_1_2), rung by rung: option, variable, sibling."""

    def rung(step: str, raw: str | None, explicit: bool, unset: str) -> data_paths.Rung:
        if not raw:
            return data_paths.Rung(step, None, explicit, unset)
        path = Path(raw).expanduser()
        ok = (path / SPLIT_DIR).is_dir()
        bad = ("invalid: " if explicit else "") + ("absent" if not path.is_dir() else f"no {SPLIT_DIR.as_posix()}")
        return data_paths.Rung(step, path, explicit, "found" if ok else bad)

    rungs = [
        rung("data_dir", data_dir, True, "not given"),
        rung(f"${DATA_ENV_2_1_2}", os.environ.get(DATA_ENV_2_1_2), True, "not set"),
    ]
    primary = data_paths.chosen(data_paths.search(LOCATION, None, stop_at_first=False))
    if primary is None or primary.path is None:
        rungs.append(data_paths.Rung("next to ALFWorld", None, False, "no ALFWorld folder"))
    else:
        rungs.append(rung("next to ALFWorld", str(primary.path.resolve().parent / SIBLING_2_1_2), False, ""))
    return rungs, data_paths.chosen(rungs)


FOLDER = DataFolder(
    name="alfworld",
    title="ALFWorld (game files 2.1.1)",
    location=LOCATION,
    groups=(Group("json_2.1.1/", fetchable=True), Group("logic/", fetchable=True)),
    sources=(
        Source("json_2.1.1_json.zip", JSON_URL, "zip"),
        Source("json_2.1.1_pddl.zip", PDDL_URL, "zip"),
        Source("json_2.1.1_tw-pddl.zip", TW_PDDL_2_1_1_URL, "zip"),
        Source("alfred.pddl", f"{LOGIC_BASE}/alfred.pddl", "file", "logic/alfred.pddl"),
        Source("alfred.twl2", f"{LOGIC_BASE}/alfred.twl2", "file", "logic/alfred.twl2"),
    ),
    member_path=member_path,
)

FOLDER_2_1_2 = DataFolder(
    name="alfworld-2.1.2",
    title="ALFWorld (game files 2.1.2)",
    location=LOCATION_2_1_2,
    groups=(Group("json_2.1.1/", fetchable=True),),
    sources=(Source("json_2.1.2_tw-pddl.zip", TW_PDDL_2_1_2_URL, "zip"),),
    member_path=member_path,
    search=search_2_1_2,
)
