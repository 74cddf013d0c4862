"""Where local sandboxes say what they hold, so that a driver can clean up after a killed worker.

A container carries its labels in Docker; a local sandbox has nothing the OS would label, so each
one writes ``<tempdir>/recap-eval-sandboxes/<id>.json`` (its labels, its temporary root, its
pids cgroup, the process group of the command running now) and removes it on close.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

REGISTRY_DIR = Path(tempfile.gettempdir()) / "recap-eval-sandboxes"


def entry_path(sandbox_id: str) -> Path:
    """The registry file of one local sandbox."""
    return REGISTRY_DIR / f"{sandbox_id}.json"


def write_entry(sandbox_id: str, entry: Mapping[str, Any]) -> None:
    """Write (atomically replace) one sandbox's entry."""
    REGISTRY_DIR.mkdir(parents=True, exist_ok=True)
    p = entry_path(sandbox_id)
    tmp = p.with_suffix(f".{os.getpid()}.tmp")
    tmp.write_text(json.dumps(dict(entry)))
    os.replace(tmp, p)


def remove_entry(sandbox_id: str) -> None:
    """Forget one sandbox (no error when it is already gone)."""
    entry_path(sandbox_id).unlink(missing_ok=True)


def entries() -> Iterator[tuple[str, dict[str, Any]]]:
    """Every registered sandbox's id and entry (unreadable files are skipped)."""
    if not REGISTRY_DIR.is_dir():
        return
    for p in sorted(REGISTRY_DIR.glob("*.json")):
        try:
            yield p.stem, json.loads(p.read_text())
        except (OSError, ValueError):
            continue


def matches(have: Mapping[str, str], want: Mapping[str, str]) -> bool:
    """Whether labels ``have`` carry every label of ``want``."""
    return all(have.get(k) == v for k, v in want.items())
