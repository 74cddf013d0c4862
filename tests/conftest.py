"""Shared test configuration: data folders from ../shared, offline litellm."""

from __future__ import annotations

import os
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = (REPO / ".." / "shared" / "data").resolve()

os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
os.environ.setdefault("ROBOTOUILLE_DATA", str(SHARED_DATA / "robotouille"))
os.environ.setdefault("ALFWORLD_DATA", str(SHARED_DATA / "alfworld"))
