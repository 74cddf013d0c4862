"""The sandbox image, built on this machine: no registry is needed (none is reachable here).

``debootstrap --variant=minbase`` writes a Debian root file system (Python 3.11, pytest, git,
GNU patch, ca-certificates) from the Debian mirror into a temporary folder; the apt caches, lists,
documentation, manual pages and locales are removed (they are most of a minbase tree's size and
nothing in an episode reads them), and the tree is tarred and ``docker import``-ed under ``tag``.
A plain ``docker build`` would need a base image from a registry; ``import`` needs none.

:func:`build_image` is idempotent (it does nothing when the tag exists and was built from this
recipe) and serialised by a lock file, so that test sessions or workers started at once build it
once. The image carries its recipe's hash (label :data:`RECIPE_LABEL`: suite, packages, trimmed
paths, image settings); an image of the tag built from another recipe (an older package list, or
none recorded) is rebuilt, so a machine never keeps evaluating in an image that lacks a program
the evaluation needs.

``patch`` is in the image because the evaluation applies a diff as the SWE-bench harness does:
``git apply`` first, GNU ``patch --batch --fuzz=5 -p1 -i`` when git refuses
(swebench/harness/run_evaluation.py:64-68 ``GIT_APPLY_CMDS``; :mod:`workers.envs.swe.evaluate`).
Without it a diff that ``patch`` applies and git refuses was resolved in the local sandbox and
``patch_failed`` in Docker (issue 36 item 3).

    bash scripts/build_sandbox_image.sh            # or: python -m workers.sandbox.image
"""

from __future__ import annotations

import argparse
import fcntl
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

DEFAULT_IMAGE = "recap-eval/sandbox:py311"
DEFAULT_SUITE = "bookworm"  # Debian 12: python3 is 3.11, the tag's "py311"
DEFAULT_MIRROR = "http://deb.debian.org/debian"
DEFAULT_PACKAGES: tuple[str, ...] = ("python3", "python-is-python3", "python3-pytest", "git", "patch", "ca-certificates")
#: the image label that holds the hash of the recipe it was built from (:func:`recipe_hash`)
RECIPE_LABEL = "org.recap-eval.sandbox.recipe"
BUILD_COMMAND = "bash scripts/build_sandbox_image.sh"

#: what the import sets (an imported tree has no image configuration of its own)
IMAGE_CHANGES: tuple[str, ...] = (
    "ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin",
    "ENV LANG=C.UTF-8",
    'CMD ["/bin/bash"]',
)

#: removed from the tree before import (paths relative to its root)
_TRIM = (
    "var/cache/apt",
    "var/lib/apt/lists",
    "var/cache/debconf/templates.dat-old",
    "usr/share/doc",
    "usr/share/man",
    "usr/share/info",
    "usr/share/locale",
    "usr/share/lintian",
    "var/log",
)

_LOCK = Path(tempfile.gettempdir()) / "recap-eval-sandbox-image.lock"


@dataclass(frozen=True)
class BuildResult:
    """What :func:`build_image` did: ``built`` False when the tag already existed."""

    tag: str
    built: bool
    seconds: float
    size_bytes: int


def _client() -> Any:
    import docker

    return docker.from_env()


def image_exists(tag: str = DEFAULT_IMAGE) -> bool:
    """Whether the local Docker daemon has ``tag`` (raises docker's errors when it is unreachable)."""
    import docker.errors

    try:
        _client().images.get(tag)
    except docker.errors.ImageNotFound:
        return False
    return True


def image_recipe(tag: str = DEFAULT_IMAGE) -> str | None:
    """The recipe hash ``tag`` was built from (its :data:`RECIPE_LABEL`), "" for an image without
    one (built before the label, or not by us), None when the daemon has no ``tag``."""
    import docker.errors

    try:
        labels = _client().images.get(tag).attrs.get("Config", {}).get("Labels") or {}
    except docker.errors.ImageNotFound:
        return None
    return str(labels.get(RECIPE_LABEL, ""))


def recipe_hash(suite: str = DEFAULT_SUITE, packages: Sequence[str] = DEFAULT_PACKAGES) -> str:
    """A short hash of what an image is built from: the suite, the packages, the trimmed paths and
    the image settings (the mirror is where it comes from, not what it is: not in it)."""
    recipe = {"suite": suite, "packages": sorted(packages), "trim": list(_TRIM), "changes": list(IMAGE_CHANGES)}
    return hashlib.sha256(json.dumps(recipe, sort_keys=True).encode("utf-8")).hexdigest()[:16]


def image_size(tag: str = DEFAULT_IMAGE) -> int:
    """The image's size in bytes as the daemon reports it."""
    return int(_client().images.get(tag).attrs.get("Size", 0))


def _debootstrap(root: Path, suite: str, mirror: str, packages: Sequence[str], log: bool) -> None:
    if shutil.which("debootstrap") is None:
        raise RuntimeError("debootstrap is not installed (apt-get install -y debootstrap)")
    cmd = ["debootstrap", "--variant=minbase", f"--include={','.join(packages)}", suite, str(root), mirror]
    proc = subprocess.run(cmd, capture_output=not log, text=True)
    if proc.returncode != 0:
        tail = (proc.stderr or proc.stdout or "")[-2000:] if not log else ""
        raise RuntimeError(f"debootstrap failed (exit {proc.returncode}): {' '.join(cmd)}\n{tail}")


def _trim(root: Path) -> None:
    for rel in _TRIM:
        p = root / rel
        if p.is_dir():
            for child in p.iterdir():
                if child.is_dir() and not child.is_symlink():
                    shutil.rmtree(child)
                else:
                    child.unlink()
    # Python's byte-code caches are rebuilt on demand
    for cache in root.glob("usr/lib/python3*/**/__pycache__"):
        shutil.rmtree(cache, ignore_errors=True)


def _import(root: Path, tag: str, recipe: str) -> None:
    repository, _, version = tag.rpartition(":")
    if not repository or "/" in version:
        repository, version = tag, "latest"
    with tempfile.NamedTemporaryFile(suffix=".tar", dir=root.parent) as tar:
        subprocess.run(["tar", "--numeric-owner", "-C", str(root), "-cf", tar.name, "."], check=True)
        _client().api.import_image_from_file(
            tar.name, repository=repository, tag=version, changes=[*IMAGE_CHANGES, f"LABEL {RECIPE_LABEL}={recipe}"]
        )


def build_image(
    tag: str = DEFAULT_IMAGE,
    *,
    suite: str = DEFAULT_SUITE,
    mirror: str = DEFAULT_MIRROR,
    packages: Sequence[str] = DEFAULT_PACKAGES,
    force: bool = False,
    log: bool = False,
) -> BuildResult:
    """Build ``tag`` unless it exists built from this recipe (:func:`recipe_hash`; ``force``
    rebuilds). Needs root (debootstrap) and the Debian mirror; takes a few minutes."""
    t0 = time.monotonic()
    recipe = recipe_hash(suite, packages)
    _LOCK.touch(exist_ok=True)
    with open(_LOCK) as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # a second builder waits here, then finds the image
        if not force and image_recipe(tag) == recipe:
            return BuildResult(tag, False, time.monotonic() - t0, image_size(tag))
        with tempfile.TemporaryDirectory(prefix="recap-sandbox-image-") as tmp:
            root = Path(tmp) / "root"
            _debootstrap(root, suite, mirror, packages, log)
            _trim(root)
            _import(root, tag, recipe)
    return BuildResult(tag, True, time.monotonic() - t0, image_size(tag))


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m workers.sandbox.image [--tag T] [--force]``: build the image if it is missing."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("--tag", default=DEFAULT_IMAGE)
    ap.add_argument("--suite", default=DEFAULT_SUITE)
    ap.add_argument("--mirror", default=DEFAULT_MIRROR)
    ap.add_argument("--force", action="store_true", help="rebuild even if the tag exists")
    args = ap.parse_args(argv)
    if os.geteuid() != 0:
        print("error: building the sandbox image needs root (debootstrap)", file=sys.stderr)
        return 2
    try:
        res = build_image(args.tag, suite=args.suite, mirror=args.mirror, force=args.force, log=True)
    except Exception as e:  # one line, not a traceback
        print(f"error: {e}", file=sys.stderr)
        return 1
    what = "built" if res.built else "already present (same recipe)"
    print(f"{res.tag}: {what} ({res.size_bytes / 1e6:.0f} MB, {res.seconds:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
