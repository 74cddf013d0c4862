"""Where a Robotouille data folder is, and how its JSON files are read.

The engine is a clean-room interpreter of the benchmark's *data* (domain, problems, generated
instances); the data stays outside the repository, so every entry point goes through this module
to find the folder (the shared rule of ``workers/envs/data_paths.py``: ``data_dir`` option, else
``ROBOTOUILLE_DATA``, else recap-eval's cache, else ``../shared/data/robotouille``) and to turn a
missing or broken file into one clear error that names it.
"""

from __future__ import annotations

import json
import os
from functools import lru_cache
from pathlib import Path
from typing import Any

from recap.env import EnvError
from workers.envs import data_paths
from workers.envs.registry import DataNotFoundError

ENV_VAR = "ROBOTOUILLE_DATA"
DOMAIN_FILE = "domain/robotouille.json"
INSTANCES_DIR = "instances"
TRAIN_INSTANCES_DIR = "instances_train"


class DataFileError(EnvError):
    """A data file exists but is not valid JSON or lacks a field the engine needs."""


def _invalid(path: Path, source: str, problem: str) -> str:
    if problem == "absent":
        return f"Robotouille data folder {str(path)!r} (from {source}) does not exist"
    return f"{str(path)!r} (from {source}) is not a Robotouille data folder: {DOMAIN_FILE} is missing"


def _missing(rungs: list[data_paths.Rung]) -> str:
    return (
        f"no Robotouille data folder: pass data_dir=... or set {ENV_VAR} "
        f"to a folder holding {DOMAIN_FILE} and {INSTANCES_DIR}/, or run `recap data fetch robotouille` "
        f"(looked in {data_paths.describe_probed(rungs)})"
    )


#: how the shared resolver (workers/envs/data_paths.py) recognises a Robotouille folder
LOCATION = data_paths.DataLocation(
    name="robotouille",
    title="Robotouille",
    env_var=ENV_VAR,
    marker=DOMAIN_FILE,
    upstream_note="none (Robotouille keeps its data inside its repository checkout)",
)


def resolve_data_dir(data_dir: str | os.PathLike[str] | None = None) -> Path:
    """The Robotouille data folder, found by the shared rule (workers/envs/data_paths.py):
    ``data_dir`` if given, else ``$ROBOTOUILLE_DATA``, else recap-eval's cache
    (``~/.cache/recap-eval/data/robotouille``), else ``<checkout>/../shared/data/robotouille``.

    Raises DataNotFoundError when a folder named by ``data_dir``/``$ROBOTOUILLE_DATA`` does not
    exist or lacks the domain file (it is not a Robotouille data folder), or when none is found.
    """
    path, _rung = data_paths.resolve(LOCATION, data_dir, invalid=_invalid, missing=_missing)
    return path


def read_json(path: Path) -> Any:
    """Parse one JSON file; a missing or malformed file raises an error naming it."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DataNotFoundError(f"Robotouille data file {str(path)!r} does not exist{_instances_hint(path)}") from None
    except OSError as exc:
        raise DataFileError(f"cannot read Robotouille data file {str(path)!r}: {exc}") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise DataFileError(
            f"malformed JSON in Robotouille data file {str(path)!r}: {exc.msg} (line {exc.lineno}, column {exc.colno})"
        ) from None


def _instances_hint(path: Path) -> str:
    """Why an instance file can be missing from a data folder (they are generated, not downloaded)."""
    if INSTANCES_DIR in path.parts or TRAIN_INSTANCES_DIR in path.parts:
        return (
            "; the benchmark instances are not stored upstream: `recap data fetch robotouille` "
            "generates instances/ and instances_train/ into a new folder, or copy them from a "
            "complete Robotouille data folder (`recap data check robotouille` lists what is missing)"
        )
    return ""


def require(mapping: Any, key: str, path: Path) -> Any:
    """``mapping[key]``, or a DataFileError naming the file and the missing field."""
    if not isinstance(mapping, dict) or key not in mapping:
        raise DataFileError(f"Robotouille data file {str(path)!r} has no field {key!r}")
    return mapping[key]


@lru_cache(maxsize=8)
def _domain_json_cached(path: str, mtime_ns: int) -> Any:
    return read_json(Path(path))


def domain_json(data_dir: Path) -> Any:
    """The domain JSON (cached per file version: every environment of a folder shares it)."""
    path = data_dir / DOMAIN_FILE
    try:
        mtime = path.stat().st_mtime_ns
    except FileNotFoundError:
        raise DataNotFoundError(f"Robotouille data file {str(path)!r} does not exist") from None
    return _domain_json_cached(str(path), mtime)


def instance_path(data_dir: Path, split: str, task: str, layout_seed: int) -> Path:
    """The generated instance file of an evaluation task and layout seed, ``instances/<split>/<task>_<layout_seed>.json``."""
    return data_dir / INSTANCES_DIR / split / f"{task}_{layout_seed}.json"


def train_instance_path(data_dir: Path, split: str, task: str, layout_seed: int) -> Path:
    """The generated instance file of a training task, ``instances_train/<split>_train/<task>_<layout_seed>.json`` (the
    demonstration's kitchen)."""
    return data_dir / TRAIN_INSTANCES_DIR / f"{split}_train" / f"{task}_{layout_seed}.json"
