"""Runs whose output folder is an object-store URI: work in a local mirror, upload as we go.

Why a mirror: the sink, the gateway's ``llm_calls`` writer and its fsync'd budget journal all
need a local file system (rename for atomic parts, fsync for the journal). So a run writes into
``~/.cache/recap-eval/mirror/<hash of the URI>/`` and the driver uploads new part files (each
one PUT, which object stores make atomic) every ``PUSH_EVERY_S`` seconds and at the end; the
small files (run.json, plan.json, spec.yaml, the journal) are re-uploaded each time. A resume on
another machine first downloads the folder into its own mirror. Part files are immutable, so
"not there yet or of another size" is all the comparison needed.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import pyarrow.fs as pafs

PUSH_EVERY_S = 60.0
#: files that change after they are written (re-uploaded on every push)
MUTABLE = ("run.json", "plan.json", "spec.yaml", "gateway/ledger.jsonl", "wiki_manifest.json")


def mirror_dir(uri: str) -> Path:
    """The local mirror folder of an object-store run ``uri``: stable per URI (hash), under ``$RECAP_EVAL_CACHE``
    or ~/.cache/recap-eval."""
    base = Path(os.environ.get("RECAP_EVAL_CACHE", Path.home() / ".cache" / "recap-eval"))
    return base / "mirror" / hashlib.sha256(uri.encode()).hexdigest()[:16]


def _remote(uri: str) -> tuple[object, str]:
    fs, root = pafs.FileSystem.from_uri(uri)
    return fs, root.rstrip("/")


def _listing(fs: object, root: str) -> dict[str, int]:
    infos = fs.get_file_info(pafs.FileSelector(root, recursive=True, allow_not_found=True))  # type: ignore[attr-defined]
    return {i.path[len(root) + 1 :]: i.size for i in infos if i.type == pafs.FileType.File}


def pull(uri: str, local: Path) -> int:
    """Download every file of the remote run folder missing (or different) locally."""
    fs, root = _remote(uri)
    n = 0
    for rel, size in _listing(fs, root).items():
        if rel.split("/")[-1].startswith(".tmp-"):
            continue
        dest = local / rel
        if dest.exists() and dest.stat().st_size == size and rel not in MUTABLE:
            continue
        dest.parent.mkdir(parents=True, exist_ok=True)
        tmp = dest.with_name(f".tmp-{dest.name}")
        with fs.open_input_stream(f"{root}/{rel}") as src, open(tmp, "wb") as out:  # type: ignore[attr-defined]
            out.write(src.read())
        os.replace(tmp, dest)
        n += 1
    return n


def _upload_order(rel: str) -> tuple[int, str]:
    """Identity first, terminal episode rows after the rows they summarise, the journal last."""
    if "/" not in rel:
        return (0, rel)
    if rel.startswith("episodes/"):
        return (2, rel)
    if rel.startswith("gateway/"):
        return (3, rel)
    return (1, rel)


def push(local: Path, uri: str) -> int:
    """Upload every local file the remote lacks (or holds at another size) and the mutable ones."""
    fs, root = _remote(uri)
    have = _listing(fs, root)
    n = 0
    for path in sorted(local.rglob("*"), key=lambda p: _upload_order(p.relative_to(local).as_posix())):
        if not path.is_file() or path.name.startswith(".tmp-"):
            continue
        rel = path.relative_to(local).as_posix()
        if rel in have and have[rel] == path.stat().st_size and rel not in MUTABLE:
            continue
        parent = f"{root}/{rel}".rsplit("/", 1)[0]
        fs.create_dir(parent, recursive=True)  # type: ignore[attr-defined]
        with open(path, "rb") as src, fs.open_output_stream(f"{root}/{rel}") as out:  # type: ignore[attr-defined]
            out.write(src.read())
        n += 1
    return n
