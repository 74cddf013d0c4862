"""The seal over a snapshot's recorded pages: one hash per request row over every field it serves,
and a manifest of ``URL -> row hash`` whose digest a run writes into its ``run.json`` when it ends.

Why (issue 35 item 10): the body's sha256 alone let a snapshot be altered and still served:
another ``encoding`` (mojibake), a body rewritten together with its sha256, one URL's row
relabelled with another's, a row deleted or added. The row hash (:func:`record_sha256`) covers
the URL, the status, the encoding, the final URL, the fetch time and the body's sha256 (so the
body too, which is checked against it); the manifest lists every request row's ``[url, row
hash]``, sorted (the rows a run read, duplicates included), and its digest is the sha256 of that
list as canonical JSON. A run folder keeps the manifest as ``wiki_manifest.json`` and its digest
in ``run.json`` (``wiki_manifest_sha256``); a folder written by :func:`.pages.write_pages` keeps
the manifest beside its tables. :func:`verify` refuses, in one line, a snapshot whose rows differ
from its manifest, or whose manifest differs from the digest its run recorded.

Old snapshots (recorded before manifests, or by a run that never ended) have no manifest: they are
refused with a line saying how to re-record them, never served unchecked.
"""

from __future__ import annotations

import hashlib
import json
import os
import uuid
from collections import Counter
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

#: the manifest's file name in a run folder (or a page folder)
MANIFEST_FILE = "wiki_manifest.json"
#: the key of the manifest's digest in ``run.json``
RUN_KEY = "wiki_manifest_sha256"
#: the manifest file's format
FORMAT = 1
#: how a refusal says to make a snapshot again
RERECORD = "re-record it (a run with wikipedia: live seals its pages when it ends)"

Entry = tuple[str, str]


class SnapshotError(ValueError):
    """A snapshot that cannot be served: no table, a body that is not its sha256, a row or a row set
    that is not what its manifest sealed, or no manifest at all."""


def _canonical(value: Any) -> bytes:
    return json.dumps(value, ensure_ascii=False, separators=(",", ":")).encode("utf-8")


def record_sha256(url: str, status: int, encoding: str, final_url: str, fetched_at: str, body_sha256: str) -> str:
    """The hash of one request row over every field a snapshot serves or shows of it."""
    return hashlib.sha256(_canonical([url, int(status), encoding, final_url, fetched_at, body_sha256])).hexdigest()


def digest(entries: Sequence[Entry]) -> str:
    """The manifest's digest: the sha256 of its sorted entries as canonical JSON."""
    return hashlib.sha256(_canonical([list(e) for e in sorted(entries)])).hexdigest()


def manifest_path(folder: Path) -> Path:
    """Where a snapshot's manifest lives: in its folder, or beside a single Parquet file."""
    return folder.with_name(folder.name + ".manifest.json") if folder.is_file() else folder / MANIFEST_FILE


def write_manifest(folder: Path, entries: Iterable[Entry]) -> str:
    """Write the manifest of ``entries`` for ``folder`` (atomically) and return its digest."""
    rows = sorted(entries)
    d = digest(rows)
    path = manifest_path(folder)
    tmp = path.with_name(f".tmp-{path.name}-{uuid.uuid4().hex[:6]}")
    tmp.write_text(json.dumps({"format": FORMAT, "digest": d, "entries": [list(e) for e in rows]}, indent=0) + "\n")
    os.replace(tmp, path)
    return d


def read_manifest(folder: Path) -> tuple[str, list[Entry]] | None:
    """(digest, entries) of ``folder``'s manifest; None when there is none; SnapshotError when unreadable."""
    path = manifest_path(folder)
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as exc:
        raise SnapshotError(f"{str(path)!r} cannot be read as a wiki page manifest ({exc})") from None
    entries = raw.get("entries") if isinstance(raw, dict) else None
    if (
        not isinstance(raw, dict)
        or raw.get("format") != FORMAT
        or not isinstance(raw.get("digest"), str)
        or not isinstance(entries, list)
        or not all(isinstance(e, list) and len(e) == 2 and all(isinstance(x, str) for x in e) for e in entries)
    ):
        raise SnapshotError(f"{str(path)!r} is not a wiki page manifest of format {FORMAT}")
    return raw["digest"], [(e[0], e[1]) for e in entries]


def verify(folder: Path, rows: Sequence[Entry], sealed: str | None, *, run_folder: bool) -> None:
    """Refuse (SnapshotError, one line) unless ``rows`` (each request row's URL and recomputed row
    hash) are exactly the manifest's entries, the manifest's digest is its entries', and for a
    run folder ``sealed`` (run.json's digest) is that digest."""
    where = str(folder)
    found = read_manifest(folder)
    if found is None or (run_folder and sealed is None):
        what = f"no {MANIFEST_FILE}" if found is None else f"no {RUN_KEY} in run.json"
        raise SnapshotError(
            f"{where!r} has no sealed page manifest ({what}: recorded before manifests, or by a run that did not end); {RERECORD}"
        )
    stated, entries = found
    if digest(entries) != stated or (run_folder and sealed != stated):
        raise SnapshotError(f"{where!r}: {MANIFEST_FILE} is not the manifest its run sealed (digest mismatch); {RERECORD}")
    have, want = Counter(rows), Counter(entries)
    if have == want:
        return
    extra = sorted((have - want).elements())
    missing = sorted((want - have).elements())
    extra_urls = {u for u, _ in extra}
    changed = sorted(u for u, _ in missing if u in extra_urls)
    if changed:
        detail = f"the row of {changed[0]!r} was changed"
    elif extra:
        detail = f"a row for {extra[0][0]!r} is not in it (added, or relabelled)"
    else:
        detail = f"the row for {missing[0][0]!r} is missing (deleted, or relabelled)"
    raise SnapshotError(f"{where!r} does not match its sealed page manifest: {detail}; {RERECORD}")
