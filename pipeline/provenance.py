"""What a run records about the code that ran it: package versions and the git revision of the checkout."""

from __future__ import annotations

import json
import subprocess
import sys
from importlib import metadata

from pipeline.raysetup import PROJECT_ROOT


def package_versions() -> str:
    """The versions of Python and of the packages a run depends on, as a JSON object (run.json's provenance)."""
    out = {"python": sys.version.split()[0]}
    for pkg in ("recap-eval", "ray", "litellm", "pyarrow", "duckdb", "pydantic", "alfworld", "textworld"):
        try:
            out[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            pass
    return json.dumps(out, sort_keys=True)


def git_revision() -> str | None:
    """The checkout's commit, ``+dirty`` when tracked files changed; None outside a git checkout."""
    try:
        r = subprocess.run(["git", "rev-parse", "HEAD"], cwd=PROJECT_ROOT, capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.TimeoutExpired):
        return None
    rev = r.stdout.strip()
    if r.returncode != 0 or not rev:
        return None
    # tracked changes only: a run folder (or any output) inside the checkout is not a code change
    dirty = subprocess.run(
        ["git", "status", "--porcelain", "--untracked-files=no"], cwd=PROJECT_ROOT, capture_output=True, text=True, timeout=10
    )
    return rev + ("+dirty" if dirty.stdout.strip() else "")
