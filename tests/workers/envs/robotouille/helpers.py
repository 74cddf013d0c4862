"""Shared paths and loaders for the Robotouille tests (data read from ../shared/data/robotouille)."""

from __future__ import annotations

import json
from functools import cache
from pathlib import Path

from workers.envs.robotouille import catalog

REPO = Path(__file__).resolve().parents[4]
DATA = (REPO / ".." / "shared" / "data" / "robotouille").resolve()


def require_data() -> Path:
    """The shared data folder; a test without it fails loudly instead of passing vacuously."""
    assert (DATA / "domain" / "robotouille.json").is_file(), f"Robotouille data missing at {DATA}"
    return DATA


@cache
def instance_record(split: str, task: str, seed: int) -> dict:
    path = require_data() / "instances" / split / f"{task}_{seed}.json"
    return json.loads(path.read_text())


def all_refs() -> list[catalog.InstanceRef]:
    return catalog.all_refs()


def one_seed_per_task(seed_index: int = 0) -> list[catalog.InstanceRef]:
    seed = catalog.LAYOUT_SEEDS[seed_index]
    return [r for r in catalog.all_refs() if r.layout_seed == seed]
