"""Where a Robotouille data folder is, and how its JSON files are read.

The engine is a clean-room interpreter of the benchmark's *data* (domain, problems, generated
instances); the data stays outside the repository, so every entry point goes through this module
to find the folder (``data_dir`` option, else ``ROBOTOUILLE_DATA``) and to turn a missing or broken
file into one clear error that names it.
"""

from __future__ import annotations

import json
import os
from functools import lru_cache
from pathlib import Path
from typing import Any

from recap.env import EnvError
from workers.envs.registry import DataNotFoundError

ENV_VAR = "ROBOTOUILLE_DATA"
DOMAIN_FILE = "domain/robotouille.json"
INSTANCES_DIR = "instances"
TRAIN_INSTANCES_DIR = "instances_train"


class DataFileError(EnvError):
    """A data file exists but is not valid JSON or lacks a field the engine needs."""


def resolve_data_dir(data_dir: str | os.PathLike[str] | None = None) -> Path:
    """The Robotouille data folder: ``data_dir`` if given, else ``$ROBOTOUILLE_DATA``.

    Raises DataNotFoundError when neither is set, the folder does not exist, or it does not hold
    the domain file (i.e. it is not a Robotouille data folder).
    """
    source = "data_dir"
    if data_dir is None:
        data_dir = os.environ.get(ENV_VAR)
        source = ENV_VAR
        if not data_dir:
            raise DataNotFoundError(
                f"no Robotouille data folder: pass data_dir=... or set {ENV_VAR} "
                "to a folder holding domain/robotouille.json and instances/"
            )
    path = Path(data_dir).expanduser()
    if not path.is_dir():
        raise DataNotFoundError(f"Robotouille data folder {str(path)!r} (from {source}) does not exist")
    if not (path / DOMAIN_FILE).is_file():
        raise DataNotFoundError(
            f"{str(path)!r} (from {source}) is not a Robotouille data folder: "
            f"{DOMAIN_FILE} is missing"
        )
    return path.resolve()


def read_json(path: Path) -> Any:
    """Parse one JSON file; a missing or malformed file raises an error naming it."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DataNotFoundError(f"Robotouille data file {str(path)!r} does not exist") from None
    except OSError as exc:
        raise DataFileError(f"cannot read Robotouille data file {str(path)!r}: {exc}") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise DataFileError(
            f"malformed JSON in Robotouille data file {str(path)!r}: {exc.msg} "
            f"(line {exc.lineno}, column {exc.colno})"
        ) from None


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


def instance_path(data_dir: Path, split: str, task: str, seed: int) -> Path:
    return data_dir / INSTANCES_DIR / split / f"{task}_{seed}.json"


def train_instance_path(data_dir: Path, split: str, task: str, seed: int) -> Path:
    return data_dir / TRAIN_INSTANCES_DIR / f"{split}_train" / f"{task}_{seed}.json"
