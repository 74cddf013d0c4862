"""Tampered snapshots (issue 35 item 10): a sealed run folder of recorded pages, then one change.

One definition of each tampering, shared by ``test_snapshot_manifest.py`` (which asserts each
refusal exactly) and the chaos lab's ``wiki`` scenario (``tests/pipeline/chaos/wiki.py``). A run
folder is made as a run makes it: ``wiki_pages`` and ``wiki_requests`` parts written by
:class:`~schemas.parts.PartWriter`, sealed as the driver seals it when a session ends
(:func:`~workers.envs.fever.pages.seal_run_folder`, its digest in ``run.json``). Each tampering
then rewrites a part file in place as an attacker with the folder would.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from schemas.parts import RUN_FILE, PartWriter
from schemas.records import WikiPageRecord, WikiRequestRecord
from workers.envs.fever.manifest import RUN_KEY
from workers.envs.fever.pages import Snapshot, SnapshotError, seal_run_folder, sha256_hex

BASE = "https://en.wikipedia.org/w/index.php?search="
A, B = BASE + "Alpha", BASE + "Beta"
BODY_A = "<html><body><p>Alpha is the first letter: café.</p></body></html>".encode()
BODY_B = b"<html><body><p>Beta is the second letter.</p></body></html>"


def request(url: str, body: bytes, episode: str = "e1", encoding: str = "utf-8") -> WikiRequestRecord:
    return WikiRequestRecord(
        episode_id=episode,
        url=url,
        sha256=sha256_hex(body),
        status=200,
        fetched_at="2024-03-01T10:00:00.000+00:00",
        final_url=url.replace("w/index.php?search=", "wiki/"),
        encoding=encoding,
    )


def page(body: bytes) -> WikiPageRecord:
    return WikiPageRecord(sha256=sha256_hex(body), body=body, size=len(body))


def seal(run: Path) -> str | None:
    """What the driver does when a session ends: the manifest, its digest in run.json."""
    data = json.loads((run / RUN_FILE).read_text())
    data[RUN_KEY] = seal_run_folder(run)
    (run / RUN_FILE).write_text(json.dumps(data))
    return data[RUN_KEY]


def sealed_run(folder: Path, *, sealed: bool = True) -> Path:
    """A run folder that read Alpha and Beta (Alpha twice), sealed when it ended."""
    folder.mkdir(parents=True)
    ident = {"run_id": "r", "run": "fever-live", "created_at": 1.0, "schema_version": 5}
    (folder / RUN_FILE).write_text(json.dumps(ident))
    PartWriter(folder, "w1").write_records("r", [page(BODY_A), page(BODY_B), request(A, BODY_A), request(B, BODY_B)])
    PartWriter(folder, "w2").write_records("r", [request(A, BODY_A, "e2")])
    if sealed:
        seal(folder)
    return folder


def _rewrite(run: Path, table: str, change: Callable[[list[dict[str, Any]]], list[dict[str, Any]]]) -> None:
    """Rewrite the first part of ``table`` with its rows changed."""
    part = sorted((run / table).glob("part-*.parquet"))[0]
    data = pq.read_table(part)
    rows = change(data.to_pylist())
    pq.write_table(pa.Table.from_pylist(rows, schema=data.schema), part)


def _where(url: str, **fields: Any) -> Callable[[list[dict[str, Any]]], list[dict[str, Any]]]:
    def change(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
        return [{**r, **fields} if r.get("url") == url else r for r in rows]

    return change


def tamper_encoding(run: Path) -> None:
    """Alpha's row says its body is cp1252: served, the text would be mojibake."""
    _rewrite(run, "wiki_requests", _where(A, encoding="cp1252"))


def tamper_body(run: Path) -> None:
    """Alpha's body rewritten, with its sha256 (in the body row and the request row) to match."""
    forged = b"<html><body><p>Alpha is a planet.</p></body></html>"
    old = sha256_hex(BODY_A)

    def pages(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
        return [
            {**r, "sha256": sha256_hex(forged), "body": forged, "size": len(forged)} if r["sha256"] == old else r for r in rows
        ]

    _rewrite(run, "wiki_pages", pages)
    for part in sorted((run / "wiki_requests").glob("part-*.parquet")):
        data = pq.read_table(part)
        rows = [{**r, "sha256": sha256_hex(forged)} if r["sha256"] == old else r for r in data.to_pylist()]
        pq.write_table(pa.Table.from_pylist(rows, schema=data.schema), part)


def tamper_relabel(run: Path) -> None:
    """Alpha's row relabelled with Beta's: the search for Alpha would be answered with Beta's page."""
    _rewrite(run, "wiki_requests", _where(A, sha256=sha256_hex(BODY_B)))


def tamper_swap_urls(run: Path) -> None:
    """The URLs of Alpha's and Beta's rows swapped: each search answered with the other's page."""

    def swap(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
        return [{**r, "url": B if r["url"] == A else A} for r in rows]

    _rewrite(run, "wiki_requests", swap)


def tamper_delete_row(run: Path) -> None:
    """Beta's request row deleted."""
    _rewrite(run, "wiki_requests", lambda rows: [r for r in rows if r["url"] != B])


def tamper_add_row(run: Path) -> None:
    """A row added: a search for Gamma answered with Beta's page."""
    PartWriter(run, "w9").write_records("r", [request(BASE + "Gamma", BODY_B)])


def tamper_reseal_manifest(run: Path) -> None:
    """A row changed and the manifest file rewritten to match it; run.json keeps the digest sealed."""
    tamper_encoding(run)
    seal_run_folder(run)  # writes the manifest file only; run.json is the driver's to write


TAMPERINGS: dict[str, Callable[[Path], None]] = {
    "encoding": tamper_encoding,
    "body+sha256": tamper_body,
    "relabel": tamper_relabel,
    "swap urls": tamper_swap_urls,
    "deleted row": tamper_delete_row,
    "added row": tamper_add_row,
    "manifest rewritten": tamper_reseal_manifest,
}


def load(run: Path) -> str | None:
    """None when the snapshot loads (would be served), else the refusal's line."""
    try:
        Snapshot(run)
    except SnapshotError as exc:
        return str(exc)
    return None
