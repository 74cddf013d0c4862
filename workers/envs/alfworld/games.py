"""Find the ALFWorld evaluation games on disk and name them with stable ids.

The evaluation set is ALFWorld's ``eval_out_of_distribution`` split (ALFRED ``valid_unseen``).
We apply the same selection rule as ``AlfredTWEnv.collect_game_files`` (a trial folder with
``traj_data.json``, a path without "movable" or "Sliced", a game file marked solvable) to the
folder itself rather than trusting a shipped list, so a damaged or partial copy is noticed.
Only the standard library is used: listing games must work without ``alfworld`` installed.

Two copies of the games exist: the primary folder (``ALFWORLD_DATA``, game-file version 2.1.1,
with ``traj_data.json``) and the 2.1.2 re-release (``move X to Y`` wording, a ``walkthrough``
per game, game files only). Both share the ``json_2.1.1/valid_unseen/<game>/<trial>`` layout.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from workers.envs import data_paths
from workers.envs.alfworld.task_types import SHORT_NAMES
from workers.envs.registry import DataNotFoundError

DATA_ENV = "ALFWORLD_DATA"
DATA_ENV_2_1_2 = "ALFWORLD_DATA_2_1_2"
#: folder name of the 2.1.2 copy when it sits next to the primary data folder
SIBLING_2_1_2 = "alfworld-2.1.2"
SPLIT_DIR = Path("json_2.1.1") / "valid_unseen"
GAME_FILE = "game.tw-pddl"
TRAJ_FILE = "traj_data.json"
BENCHMARK_NAME = "alfworld"
#: ALFWorld's own default download folder (alfworld/info.py: os.path.expanduser("~/.cache/alfworld"))
UPSTREAM_CACHE = "~/.cache/alfworld"


@dataclass(frozen=True)
class Game:
    """One evaluation game: where it lives (relative to a data folder) and its task type."""

    short_type: str  # "heat"
    task_type: str  # "pick_heat_then_place_in_recep"
    game_dir: str  # "pick_heat_then_place_in_recep-Mug-None-Cabinet-10"
    trial: str  # "trial_T20190909_021100_341887"

    @property
    def instance_id(self) -> str:
        """The stable id of the game: ``alfworld/<task type>/<game folder>/<trial>``."""
        return f"{BENCHMARK_NAME}/{self.short_type}/{self.game_dir}/{self.trial}"

    @property
    def relpath(self) -> Path:
        """The trial folder relative to a data folder (same in both versions)."""
        return SPLIT_DIR / self.game_dir / self.trial

    def game_file(self, data_dir: Path) -> Path:
        """The game file (game.tw-pddl) of this trial under ``data_dir``."""
        return data_dir / self.relpath / GAME_FILE


#: how each game-file version spells "put an object down" in the grammar of a game.tw-pddl
_WORDING_MARKS = {"2.1.1": b"put {o} in/on {r}", "2.1.2": b"move {o} to {r}"}


def game_file_version(folder: Path) -> str | None:
    """The wording version ("2.1.1"/"2.1.2") of the first game file under ``folder``, or None
    when there is none or it is unreadable (reads one file; used to probe implicit folders)."""
    split = folder / SPLIT_DIR
    try:
        for game_dir in sorted(p for p in split.iterdir() if p.is_dir()):
            for trial in sorted(p for p in game_dir.iterdir() if p.is_dir()):
                game_file = trial / GAME_FILE
                if game_file.is_file():
                    text = game_file.read_bytes()
                    for version, mark in _WORDING_MARKS.items():
                        if mark in text:
                            return version
                    return None
    except OSError:
        return None
    return None


def _probe_2_1_1(folder: Path) -> str | None:
    """Why a probed folder cannot serve as the primary (2.1.1) folder, or None."""
    version = game_file_version(folder)
    if version == "2.1.1":
        return None
    if version == "2.1.2":
        return (
            "holds game-file version 2.1.2 (what alfworld 0.4.2's alfworld-download fetches); "
            f"it can serve as the 2.1.2 folder ({DATA_ENV_2_1_2}); "
            "`recap data fetch alfworld` gets the 2.1.1 games"
        )
    return "no readable game file"


def _invalid(path: Path, source: str, problem: str) -> str:
    return (
        f"ALFWorld data folder {path.resolve()} (from {source}) has no {SPLIT_DIR.as_posix()}; "
        f"point {source} at the folder that holds it"
    )


def _missing(rungs: list[data_paths.Rung]) -> str:
    return (
        f"ALFWorld data folder not set: set {DATA_ENV} (or pass data_dir=) to the folder "
        f"that holds {SPLIT_DIR.as_posix()}, or run `recap data fetch alfworld` "
        f"(looked in {data_paths.describe_probed(rungs)})"
    )


#: how the shared resolver (workers/envs/data_paths.py) recognises the primary ALFWorld folder
LOCATION = data_paths.DataLocation(
    name=BENCHMARK_NAME,
    title="ALFWorld",
    env_var=DATA_ENV,
    marker=SPLIT_DIR.as_posix(),
    upstream_cache=UPSTREAM_CACHE,
    probe=_probe_2_1_1,
)


def resolve_data_dir(data_dir: str | os.PathLike[str] | None = None) -> Path:
    """The primary (2.1.1) data folder, found by the shared rule (workers/envs/data_paths.py):
    ``data_dir`` if given, else ``$ALFWORLD_DATA``, else ALFWorld's own cache
    (``~/.cache/alfworld``), else recap-eval's cache (``~/.cache/recap-eval/data/alfworld``),
    else ``<checkout>/../shared/data/alfworld``. The caches and the checkout folder are used
    only when they hold 2.1.1 game files; a folder named by ``data_dir``/``$ALFWORLD_DATA``
    without ``json_2.1.1/valid_unseen`` is an error."""
    path, _rung = data_paths.resolve(LOCATION, data_dir, invalid=_invalid, missing=_missing)
    return path


def resolve_data_dir_2_1_2(primary: Path, data_dir_2_1_2: str | os.PathLike[str] | None = None) -> Path | None:
    """The 2.1.2 folder: ``data_dir_2_1_2``, else ``$ALFWORLD_DATA_2_1_2``, else the sibling
    ``<primary>/../alfworld-2.1.2``; None when none is configured and no sibling exists.

    A folder named explicitly (option or variable) that is not the expected layout is an error;
    a missing sibling is not (the caller decides whether 2.1.2 data is required).
    """
    explicit = data_dir_2_1_2 if data_dir_2_1_2 is not None else os.environ.get(DATA_ENV_2_1_2)
    if explicit:
        path = Path(explicit).expanduser().resolve()
        if not (path / SPLIT_DIR).is_dir():
            source = "data_dir_2_1_2" if data_dir_2_1_2 is not None else DATA_ENV_2_1_2
            raise DataNotFoundError(
                f"ALFWorld 2.1.2 data folder {path} (from {source}) has no "
                f"{SPLIT_DIR.as_posix()}; point {source} at the alfworld-2.1.2 folder"
            )
        return path
    sibling = (primary.parent / SIBLING_2_1_2).resolve()
    return sibling if (sibling / SPLIT_DIR).is_dir() else None


@lru_cache(maxsize=8)
def _discover(primary: str) -> tuple[Game, ...]:
    split = Path(primary) / SPLIT_DIR
    games = []
    for trial_dir in sorted(p for p in split.glob("*/*") if p.is_dir()):
        rel = trial_dir.relative_to(split).as_posix()
        if "movable" in rel or "Sliced" in rel:
            continue
        traj = trial_dir / TRAJ_FILE
        game_file = trial_dir / GAME_FILE
        if not traj.is_file() or not game_file.is_file():
            continue
        task_type = _read_json(traj).get("task_type")
        if task_type not in SHORT_NAMES:
            continue
        if _read_json(game_file).get("solvable") is not True:
            continue
        games.append(Game(SHORT_NAMES[task_type], task_type, trial_dir.parent.name, trial_dir.name))
    games.sort(key=lambda g: g.relpath.as_posix())
    return tuple(games)


def discover_games(primary: Path) -> tuple[Game, ...]:
    """The evaluation games in ``primary``, sorted by path (the order of ALFWorld's own listing)."""
    games = _discover(str(primary))
    if not games:
        raise DataNotFoundError(
            f"no playable ALFWorld games under {primary / SPLIT_DIR}; "
            f"point {DATA_ENV} (or data_dir=) at a complete copy of the data"
        )
    return games


def load_walkthrough(data_dir_2_1_2: Path, game: Game) -> tuple[str, ...]:
    """The winning command list stored in the 2.1.2 game file (2.1.2 wording)."""
    path = game.game_file(data_dir_2_1_2)
    if not path.is_file():
        raise DataNotFoundError(f"ALFWorld 2.1.2 game file missing: {path}; the 2.1.2 folder must hold all 134 games")
    walkthrough = _read_json(path).get("walkthrough")
    if not isinstance(walkthrough, list) or not all(isinstance(a, str) for a in walkthrough):
        raise DataNotFoundError(f"ALFWorld 2.1.2 game file {path} has no walkthrough list")
    return tuple(walkthrough)


def _read_json(path: Path) -> dict:
    try:
        with path.open(encoding="utf-8") as f:
            data = json.load(f)
    except (OSError, json.JSONDecodeError) as exc:
        raise DataNotFoundError(f"unreadable ALFWorld file {path}: {exc}") from None
    if not isinstance(data, dict):
        raise DataNotFoundError(f"ALFWorld file {path} is not a JSON object")
    return data
