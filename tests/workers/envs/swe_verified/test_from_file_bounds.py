"""``recap data fetch swebench-verified --from FILE`` on hostile files (issue 35 item 11): checked
while streamed, bounded, each refusal one ``FILE:LINE`` line, exit 2, nothing written.

The attacks are the chaos lab's (``tests/pipeline/chaos/user_files.py``, scenario ``userfiles``)."""

from __future__ import annotations

import hashlib
import json
import os
import threading
from pathlib import Path

import pytest

from tests.pipeline.chaos.user_files import (
    FIFO_BOUND,
    PATCHES,
    Materials,
    fetch_deep_line,
    fetch_deep_test_list,
    fetch_from,
    fetch_long_line,
    fetch_million_first_bad_fifo,
    fetch_record,
    materials,
)

PREFIX = "recap: error: data: swebench-verified: "
SUFFIX = "; nothing was written"


@pytest.fixture(scope="module")
def m(tmp_path_factory: pytest.TempPathFactory) -> Materials:
    return materials(tmp_path_factory.mktemp("userfiles"))


def test_the_first_bad_record_of_a_million_is_refused_after_a_bounded_prefix(m: Materials, tmp_path: Path) -> None:
    """Fed through a FIFO: the writer can push only what the reader takes in (plus the pipe's
    buffer), so ``sent`` is what was read. Reading all 1.27 GB first, as before, would take it all;
    a FIFO was refused outright ("is not a file")."""
    res = fetch_million_first_bad_fifo(m, tmp_path)
    assert (res.code, res.err, res.written) == (2, [f"{PREFIX}million.jsonl:1: missing field 'repo'{SUFFIX}"], [])
    assert res.extra["total"] > 10**9 and res.extra["sent"] < FIFO_BOUND
    assert not res.extra["writer_stuck"]


def test_a_good_file_through_a_fifo_is_stored_with_the_digest_of_what_was_read(m: Materials, tmp_path: Path) -> None:
    fifo = tmp_path / "verified.jsonl"
    os.mkfifo(fifo)
    body = "".join(json.dumps(m.verified(i)) + "\n" for i in (0, 1)).encode()
    writer = threading.Thread(target=lambda: fifo.write_bytes(body), daemon=True)
    writer.start()
    res = fetch_from(tmp_path, fifo)
    writer.join(timeout=30)
    assert (res.code, res.err) == (0, [])
    folder = tmp_path / "cache" / "data" / "swebench-verified"
    source = json.loads((folder / "SOURCE.json").read_text())
    assert (source["instances"], source["subset"], source["source_sha256"]) == (2, True, hashlib.sha256(body).hexdigest())
    assert [json.loads(line) for line in (folder / "instances.jsonl").read_text().splitlines()] == [m.verified(0), m.verified(1)]


def test_deep_nesting_is_one_file_line_exit_2(m: Materials, tmp_path: Path) -> None:
    """200,000 brackets on line 2 (the first record good): refused before json recurses; before,
    ``maximum recursion depth exceeded`` with exit 1 and no file:line."""
    res = fetch_deep_line(m, tmp_path / "line")
    assert (res.code, res.err, res.written) == (
        2,
        [f"{PREFIX}deep.jsonl:2: nested deeper than 64 levels of arrays/objects{SUFFIX}"],
        [],
    )
    res = fetch_deep_test_list(m, tmp_path / "list")
    assert (res.code, res.written) == (2, [])
    assert res.err == [
        f"{PREFIX}deep.jsonl:1: field 'FAIL_TO_PASS' is not a JSON-encoded list (nested deeper than 64 levels of "
        f"arrays/objects){SUFFIX}"
    ]


def test_a_line_past_16_mib_is_refused_without_being_read_whole(m: Materials, tmp_path: Path) -> None:
    res = fetch_long_line(m, tmp_path)
    assert (res.code, res.err, res.written) == (
        2,
        [f"{PREFIX}long.jsonl:1: longer than 16777216 bytes (one record a line){SUFFIX}"],
        [],
    )


def test_an_id_with_dotdot_and_a_gold_patch_out_of_the_repository_are_refused(m: Materials, tmp_path: Path) -> None:
    res = fetch_record(m, tmp_path / "id", {"instance_id": "fixture__off..byone-1", "repo": "fixture/off..byone"})
    assert (res.code, res.written) == (2, [])
    assert res.err == [
        f"{PREFIX}verified.jsonl:1: instance_id must be letters, digits, '_', '.' and '-' (starting with a letter or "
        f"digit, no '..'), got 'fixture__off..byone-1'{SUFFIX}"
    ]
    res = fetch_record(m, tmp_path / "patch", {"patch": PATCHES["dotdot"]})
    assert (res.code, res.written) == (2, [])
    assert res.err == [
        f"{PREFIX}verified.jsonl:1: field 'patch': line 1 of the patch names 'a/../outside.py' (a '..' component), "
        f"outside the repository{SUFFIX}"
    ]
    res = fetch_record(m, tmp_path / "test_patch", {"test_patch": PATCHES["symlink out"]})
    assert res.err == [
        f"{PREFIX}verified.jsonl:1: field 'test_patch': line 6 of the patch creates the symlink 'etc' to '/etc', "
        f"outside the repository{SUFFIX}"
    ]


def test_a_parquet_copy_is_held_to_the_same_bounds(m: Materials, tmp_path: Path) -> None:
    """Read a batch at a time, the dataset's columns only; a deep test list is one line, exit 2."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    deep = {**m.verified(0), "FAIL_TO_PASS": "[" * 100_000 + "]" * 100_000}
    src = tmp_path / "verified.parquet"
    pq.write_table(pa.Table.from_pylist([m.verified(1), deep]), src)
    res = fetch_from(tmp_path, src)
    assert (res.code, res.written) == (2, [])
    assert res.err == [
        f"{PREFIX}verified.parquet:row 2: field 'FAIL_TO_PASS' is not a JSON-encoded list (nested deeper than 64 "
        f"levels of arrays/objects){SUFFIX}"
    ]


def test_the_record_past_the_full_split_is_refused_where_it_is(m: Materials, tmp_path: Path) -> None:
    """The 501st record is refused by its line; before, all were read and counted first."""
    rec = m.verified()
    rows = [{**rec, "instance_id": f"fixture__offbyone-{n}"} for n in range(1, 601)]
    src = tmp_path / "verified.jsonl"
    src.write_text("".join(json.dumps(r) + "\n" for r in rows), encoding="utf-8")
    res = fetch_from(tmp_path, src)
    assert (res.code, res.written) == (2, [])
    assert res.err == [
        f"{PREFIX}verified.jsonl:501: more records than the 500 of princeton-nlp/SWE-bench_Verified (test){SUFFIX}"
    ]
