"""The run folder's wiki tables: one ``wiki_pages`` row per body and run however many workers wrote
it (the rows as written stay in ``wiki_pages_raw``), and a snapshot cache that sees parts a run is
still writing."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pipeline.cli import main
from schemas.parts import RUN_FILE, PartWriter
from schemas.records import WikiPageRecord, WikiRequestRecord
from workers.envs.fever.benchmark import wiki_source
from workers.envs.fever.manifest import RUN_KEY
from workers.envs.fever.pages import SnapshotError, seal_run_folder, sha256_hex
from workers.envs.fever.wiki import SnapshotSource, WikiError

BODY = b"<html>a page</html>"
OTHER = b"<html>another page</html>"


def _request(url: str, body: bytes, episode: str) -> WikiRequestRecord:
    return WikiRequestRecord(
        episode_id=episode,
        url=url,
        sha256=sha256_hex(body),
        status=200,
        fetched_at="2024-03-01T10:00:00Z",
        final_url=url,
        encoding="utf-8",
    )


def _run_folder(path: Path, run_id: str) -> Path:
    path.mkdir(parents=True)
    (path / RUN_FILE).write_text(json.dumps({"run_id": run_id}), encoding="utf-8")
    return path


def _page(body: bytes) -> WikiPageRecord:
    return WikiPageRecord(sha256=sha256_hex(body), body=body, size=len(body))


def test_wiki_pages_holds_each_body_once_per_run(tmp_path, capsys):
    a, b = _run_folder(tmp_path / "a", "run-a"), _run_folder(tmp_path / "b", "run-b")
    # two workers of run a read the same page and each wrote it; run b read it too
    PartWriter(a, "w1").write_records("run-a", [_page(BODY), _request("http://w/1", BODY, "e1")])
    PartWriter(a, "w2").write_records("run-a", [_page(BODY), _page(OTHER), _request("http://w/2", OTHER, "e2")])
    PartWriter(b, "w1").write_records("run-b", [_page(BODY)])
    query = "select run_id, count(*) n, sum(size) bytes from wiki_pages group by 1 order by 1"
    assert main(["sql", str(a), str(b), "--csv", query]) == 0
    assert capsys.readouterr().out == f"run_id,n,bytes\nrun-a,2,{len(BODY) + len(OTHER)}\nrun-b,1,{len(BODY)}\n"
    assert main(["sql", str(a), "--csv", "select count(*) n from wiki_pages_raw"]) == 0
    assert capsys.readouterr().out == "n\n3\n"


def seal(run: Path) -> None:
    """What the driver does when a session ends: the manifest, its digest in run.json."""
    data = json.loads((run / RUN_FILE).read_text())
    data[RUN_KEY] = seal_run_folder(run)
    (run / RUN_FILE).write_text(json.dumps(data))


def test_the_snapshot_cache_sees_parts_written_after_it_was_loaded(tmp_path):
    run = _run_folder(tmp_path / "run", "r")
    PartWriter(run, "w1").write_records("r", [_page(BODY), _request("http://w/1", BODY, "e1")])
    seal(run)
    first = wiki_source(f"snapshot:{run}")
    assert isinstance(first, SnapshotSource) and first.fetch("http://w/1") == BODY.decode()
    # a later session of the same run writes more parts (the table folders' own mtimes need not
    # change): refused until that session ends and seals them
    PartWriter(run, "w2").write_records("r", [_page(OTHER), _request("http://w/2", OTHER, "e2")])
    with pytest.raises(SnapshotError, match="a row for 'http://w/2' is not in it"):
        wiki_source(f"snapshot:{run}")
    seal(run)
    again = wiki_source(f"snapshot:{run}")
    assert again.fetch("http://w/2") == OTHER.decode()
    assert wiki_source(f"snapshot:{run}").snapshot is again.snapshot  # unchanged parts: the cached one
    with pytest.raises(WikiError, match="^snapshot_miss: "):
        again.fetch("http://w/3")
