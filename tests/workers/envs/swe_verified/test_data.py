"""``recap data fetch/check swebench-verified`` and ``recap env list swe-verified`` through the CLI."""

from __future__ import annotations

import json

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from pipeline.cli import main
from workers.envs.swe_verified import images

from .conftest import write_jsonl


def cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, list[str], list[str]]:
    code = main(list(argv))
    got = capsys.readouterr()
    return code, got.out.splitlines(), got.err.splitlines()


@pytest.fixture
def no_images(monkeypatch: pytest.MonkeyPatch) -> None:
    """No Docker image is here (the listing is one call; the tests answer it)."""
    monkeypatch.setattr("workers.envs.swe_verified.data_folders.local_images", lambda: set())


def test_fetch_a_subset_then_check_and_list(tmp_path, records, cache, capsys, no_images) -> None:
    src = write_jsonl(tmp_path / "verified.jsonl", records)
    code, out, err = cli(capsys, "data", "fetch", "swebench-verified", "--from", str(src), "--subset")
    assert (code, err) == (0, [])
    assert out == [
        f"swebench-verified: loading {src}",
        f"swebench-verified: {cache}: 2 files stored and verified",
        "swebench-verified: note: each instance runs in the SWE-bench harness's image; "
        "`recap data check swebench-verified` says which are here",
    ]
    assert sorted(p.name for p in cache.iterdir()) == ["MANIFEST.sha256", "SOURCE.json", "instances.jsonl"]
    source = json.loads((cache / "SOURCE.json").read_text())
    assert (source["instances"], source["subset"], source["source"]) == (3, True, str(src))
    stored = [json.loads(line) for line in (cache / "instances.jsonl").read_text().splitlines()]
    assert stored == records

    code, out, err = cli(capsys, "data", "check", "swebench-verified")
    missing = [images.remote_image(f"fixture__{n}-1") for n in ("offbyone", "format", "twofiles")]
    assert (code, err) == (0, [])
    assert out == [
        f"swebench-verified: {cache} (recap-eval cache): 2 files checked: OK",
        f"swebench-verified: 3 instances (a subset of the 500) from {src}",
        "swebench-verified: images: 0 of 3 instances have their image locally; 3 missing: "
        + ", ".join(missing)
        + f"; get them with `docker pull {missing[0]}` (and the others) where Docker Hub is reachable, or build them "
        "with the SWE-bench harness (python -m swebench.harness.prepare_images --dataset_name "
        "princeton-nlp/SWE-bench_Verified --instance_ids ...)",
    ]

    code, out, err = cli(capsys, "env", "list", "swe-verified")
    assert (code, out, err) == (
        0,
        ["swe-verified/fixture__offbyone-1", "swe-verified/fixture__format-1", "swe-verified/fixture__twofiles-1"],
        ["3 instances"],
    )
    assert cli(capsys, "env", "list", "swe-verified", "fixture/format")[1] == ["swe-verified/fixture__format-1"]
    assert cli(capsys, "env", "list", "swe-verified", "fixture__twofiles-1")[1] == ["swe-verified/fixture__twofiles-1"]
    code, out, err = cli(capsys, "env", "list", "swe-verified", "django/django")
    assert code == 2 and out == [] and len(err) == 1
    assert "no SWE-bench Verified instance is 'django/django'" in err[0]

    # the same file again: already there; a corrupted stored file fails the check
    code, out, _ = cli(capsys, "data", "fetch", "swebench-verified", "--from", str(src), "--subset")
    assert code == 0 and out[-1] == f"swebench-verified: {cache} is already there and holds the same records (2 files)"
    (cache / "instances.jsonl").write_text("{}\n")
    code, out, err = cli(capsys, "data", "check", "swebench-verified")
    assert code == 1
    assert out == [
        f"swebench-verified: {cache} (recap-eval cache): 2 files checked: 0 missing, 1 mismatched (e.g. instances.jsonl); "
        "fetch a fresh copy: `recap data fetch swebench-verified --dest NEW_FOLDER`: FAILED"
    ]


def test_images_line_counts_the_present_ones(tmp_path, records, cache, capsys, monkeypatch) -> None:
    src = write_jsonl(tmp_path / "verified.jsonl", records)
    assert cli(capsys, "data", "fetch", "swebench-verified", "--from", str(src), "--subset")[0] == 0
    present = {images.remote_image("fixture__offbyone-1"), images.local_image("fixture__format-1"), "python:3.11"}
    calls = []
    monkeypatch.setattr("workers.envs.swe_verified.data_folders.local_images", lambda: calls.append(1) or present)
    code, out, _ = cli(capsys, "data", "check", "swebench-verified")
    assert code == 0 and calls == [1]
    missing = images.remote_image("fixture__twofiles-1")
    assert out[-1].startswith(f"swebench-verified: images: 2 of 3 instances have their image locally; 1 missing: {missing}; ")


def test_parquet_copy_is_read_like_jsonl(tmp_path, records, cache, capsys, no_images) -> None:
    rows = [{**r, "FAIL_TO_PASS": json.loads(r["FAIL_TO_PASS"])} for r in records]  # a list column, as some copies hold
    src = tmp_path / "verified.parquet"
    pq.write_table(pa.Table.from_pylist(rows), src)
    code, _, err = cli(capsys, "data", "fetch", "swebench-verified", "--from", str(src), "--subset")
    assert (code, err) == (0, [])
    assert [json.loads(line) for line in (cache / "instances.jsonl").read_text().splitlines()] == records


def _bad(records: list[dict[str, str]], case: str) -> tuple[list[object] | str, str]:
    """A bad input file's rows (or raw text) and the error the fetch must say about it."""
    if case == "missing field":
        r = dict(records[1])
        del r["test_patch"]
        return [records[0], r, records[2]], "verified.jsonl:2: missing field 'test_patch'"
    if case == "duplicate id":
        return [records[0], records[1], records[0]], (
            "verified.jsonl:3: duplicate instance_id 'fixture__offbyone-1' (first at verified.jsonl:1)"
        )
    if case == "bad id":
        return [records[0], {**records[1], "instance_id": "fixture-format-1"}], (
            "verified.jsonl:2: instance_id 'fixture-format-1' is not of the form owner__repo-NUMBER"
        )
    if case == "id of another repo":
        return [{**records[0], "repo": "other/offbyone"}], (
            "verified.jsonl:1: instance_id 'fixture__offbyone-1' does not belong to repo 'other/offbyone'"
        )
    if case == "wrong type":
        return [{**records[0], "version": 0.1}], "verified.jsonl:1: field 'version' must be a string, got float"
    if case == "empty FAIL_TO_PASS":
        return [{**records[0], "FAIL_TO_PASS": "[]"}], (
            "verified.jsonl:1: field 'FAIL_TO_PASS' is empty (an instance needs a test its fix makes pass)"
        )
    if case == "test list not JSON":
        return [
            {**records[0], "PASS_TO_PASS": "tests/a.py::b"}
        ], "verified.jsonl:1: field 'PASS_TO_PASS' is not a JSON-encoded list"
    if case == "not JSON":
        return json.dumps(
            records[0]
        ) + "\n{not json\n", "verified.jsonl:2: not valid JSON (Expecting property name enclosed in double quotes at column 2)"
    if case == "not an object":
        return [[1, 2]], "verified.jsonl:1: a record must be an object, got list"
    raise AssertionError(case)


BAD = [
    "missing field",
    "duplicate id",
    "bad id",
    "id of another repo",
    "wrong type",
    "empty FAIL_TO_PASS",
    "test list not JSON",
    "not JSON",
    "not an object",
]


@pytest.mark.parametrize("case", BAD)
def test_bad_file_is_one_line_exit_2_nothing_written(tmp_path, records, cache, capsys, case) -> None:
    rows, why = _bad(records, case)
    src = tmp_path / "verified.jsonl"
    if isinstance(rows, str):
        src.write_text(rows)
    else:
        write_jsonl(src, rows)
    code, _, err = cli(capsys, "data", "fetch", "swebench-verified", "--from", str(src), "--subset")
    assert code == 2
    assert err == [f"recap: error: data: swebench-verified: {why}; nothing was written"]
    assert not cache.exists() and not cache.parent.exists()


def test_wrong_count_without_subset_is_refused(tmp_path, records, cache, capsys) -> None:
    src = write_jsonl(tmp_path / "verified.jsonl", records)
    code, _, err = cli(capsys, "data", "fetch", "swebench-verified", "--from", str(src))
    assert code == 2
    assert err == [
        "recap: error: data: swebench-verified: 3 records, not the 500 of princeton-nlp/SWE-bench_Verified (test); "
        "pass --subset to store them as a subset; nothing was written"
    ]
    assert not cache.parent.exists()


def test_a_bad_file_never_replaces_a_stored_folder(tmp_path, records, cache, capsys, no_images) -> None:
    src = write_jsonl(tmp_path / "verified.jsonl", records)
    assert cli(capsys, "data", "fetch", "swebench-verified", "--from", str(src), "--subset")[0] == 0
    before = {p.name: p.read_bytes() for p in cache.iterdir()}
    bad = write_jsonl(tmp_path / "bad.jsonl", [records[0], records[0]])
    assert cli(capsys, "data", "fetch", "swebench-verified", "--from", str(bad), "--subset")[0] == 2
    other = write_jsonl(tmp_path / "other.jsonl", records[:2])
    code, _, err = cli(capsys, "data", "fetch", "swebench-verified", "--from", str(other), "--subset")
    assert code == 1
    assert err == [
        f"recap: error: data fetch: swebench-verified: {cache} exists and holds other files; remove it or pass another "
        "--dest; nothing was written"
    ]
    assert {p.name: p.read_bytes() for p in cache.iterdir()} == before


@pytest.mark.parametrize(
    "argv, why",
    [
        (
            ["fetch", "fever", "--from", "x.jsonl"],
            "--from is for a folder loaded from a file (swebench-verified): name it as BENCH",
        ),
        (["fetch", "--subset"], "--subset is for a folder loaded from a file (swebench-verified): name it as BENCH"),
        (
            ["fetch", "swebench-verified", "--mirror", "/tmp"],
            "--mirror does not apply to swebench-verified: pass a local copy with --from FILE",
        ),
    ],
)
def test_flags_for_the_wrong_folder_are_usage_errors(cache, capsys, argv, why) -> None:
    code, _, err = cli(capsys, "data", *argv)
    assert (code, err) == (2, [f"recap: error: data: {why}"])
    assert not cache.parent.exists()


def test_no_datasets_hub_is_one_line(cache, capsys, monkeypatch) -> None:
    import builtins

    real = builtins.__import__

    def no_datasets(name, *a, **k):
        if name == "datasets":
            raise ImportError("no datasets")
        return real(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_datasets)
    code, _, err = cli(capsys, "data", "fetch", "swebench-verified")
    assert code == 1
    assert err == [
        "recap: error: data fetch: swebench-verified: the datasets library is not installed (pip install "
        "'recap-eval[swe]'); or download princeton-nlp/SWE-bench_Verified (test) elsewhere and pass --from FILE "
        "(Parquet or JSONL); nothing was written"
    ]
    assert not cache.parent.exists()


def test_no_folder_lists_as_not_found(cache, capsys) -> None:
    code, out, err = cli(capsys, "env", "list", "swe-verified")
    assert code == 2 and out == [] and len(err) == 1
    assert "no SWE-bench Verified data folder: run `recap data fetch swebench-verified`" in err[0]
