"""Which argument is what, through the real ``recap`` entry: a query is never taken for a path,
and ``recap report`` writes only under a run folder's report/ or ``--out``, never into a folder
that is not a run folder or that holds files a report did not write (exit 2, nothing written)."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest

from pipeline.cli import main as recap_main
from tests.reports.test_sql_read_only import _snapshot

SCHEMES = "file://, s3://, gs://, gcs://, hdfs://, abfs://, abfss://"


def _cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    rc = recap_main(argv)
    got = capsys.readouterr()
    return rc, got.out, got.err


@pytest.fixture
def run(run_a: Path, tmp_path: Path) -> Path:
    dest = tmp_path / "run"
    shutil.copytree(run_a, dest)
    return dest


# -- recap sql: the last positional is the query, whatever it holds ---------------------------------

URL_QUERIES = [
    "SELECT 's3://bucket/runs/demo' AS u",
    "SELECT 'file:///etc/passwd' AS u",
    "SELECT 'gs://b/x' AS u",
    "SELECT 'http://example.org/a b' AS u",
    "SELECT 'hdfs://nn:8020/x' AS u",
    "SELECT 'abfss://c@a.dfs.core.windows.net/x' AS u",
    "SELECT 'mailto://x' AS u",
    "SELECT '://' AS u",
]


@pytest.mark.parametrize("query", URL_QUERIES)
def test_a_query_holding_a_uri_is_a_query(query, run, capsys):
    rc, out, err = _cli(["sql", str(run), query, "--json"], capsys)
    assert (rc, err) == (0, "")
    assert json.loads(out) == [{"u": query.split("'")[1]}]
    # and with several run folders, options anywhere
    rc, out, err = _cli(["sql", "--json", str(run), str(run), query], capsys)
    assert (rc, err, json.loads(out)) == (0, "", [{"u": query.split("'")[1]}])


def test_a_uri_in_a_query_file_is_a_query(run, tmp_path, capsys):
    q = tmp_path / "q.sql"
    q.write_text("SELECT 's3://x/y' AS u")
    rc, out, err = _cli(["sql", "--file", str(q), str(run), "--csv"], capsys)
    assert (rc, out, err) == (0, "u\ns3://x/y\n", "")


@pytest.mark.parametrize(
    "argv,line",
    [
        (
            ["http://example.org/run", "SELECT 1"],
            f"recap: error: sql: http://example.org/run is not a run folder: unknown URI scheme 'http' (a local folder or {SCHEMES})",
        ),
        (
            ["ftp://h/r", "SELECT 1"],
            f"recap: error: sql: ftp://h/r is not a run folder: unknown URI scheme 'ftp' (a local folder or {SCHEMES})",
        ),
        (
            ["SELECT 1", "{run}"],
            "recap: error: sql: 'SELECT 1' is not a folder; the query comes last: recap sql RUN_DIR ... QUERY",
        ),
        (
            ["{run}", "{run}"],
            "recap: error: sql: the last argument is the query, but {run} is a folder; add the QUERY after the run folders",
        ),
        (["{run}/nope", "SELECT 1"], "recap: error: sql: run folder {run}/nope does not exist or is not a folder"),
        (["{run}/episodes", "SELECT 1"], "recap: error: sql: {run}/episodes is not a run folder (no run.json)"),
        (
            ["{run}", "SELECT 1", "--memory-limit", "1GiB", "--timeout", "0"],
            "recap: error: sql: argument --timeout: must be a finite number of seconds > 0, got '0'",
        ),
        (
            ["{run}", "SELECT 1", "--timeout", "inf"],
            "recap: error: sql: argument --timeout: must be a finite number of seconds > 0, got 'inf'",
        ),
        (
            ["{run}", "SELECT 1", "--memory-limit", "100MB"],
            "recap: error: sql: argument --memory-limit: 100MB is too small; at least 256MB",
        ),
        (
            ["{run}", "SELECT 1", "--memory-limit", "2"],
            "recap: error: sql: argument --memory-limit: invalid size '2': a unit is needed, e.g. 2MB or 2GB",
        ),
        (
            ["{run}", "SELECT 1", "--memory-limit", "2 parsecs"],
            "recap: error: sql: argument --memory-limit: invalid size '2 parsecs'; give a number and a unit, e.g. 2GB, 512MB or 1.5GiB",
        ),
    ],
)
def test_run_folder_and_limit_errors_are_one_line_exit_2(argv, line, run, capsys):
    before = _snapshot(run)
    rc, out, err = _cli(["sql", *(a.format(run=run) for a in argv)], capsys)
    assert (rc, out, err) == (2, "", line.format(run=run) + "\n")
    assert _snapshot(run) == before


def test_limits_that_are_not_hit_change_nothing(run, capsys):
    rc, out, err = _cli(
        ["sql", str(run), "SELECT count(*) AS n FROM episodes", "--memory-limit", "1.5GiB", "--timeout", "600", "--csv"], capsys
    )
    assert (rc, out, err) == (0, "n\n19\n", "")


# -- recap report: a run folder, and only its report/ or --out --------------------------------------


def _folder_with_files(root: Path) -> Path:
    root.mkdir()
    (root / "notes.txt").write_text("mine\n")
    (root / "episodes").mkdir()  # a table folder's name does not make a run folder
    (root / "episodes" / "x.parquet").write_bytes(b"not a part")
    (root / "report.md").write_text("my own report.md\n")
    return root


def test_report_refuses_a_folder_without_run_json_and_writes_nothing(tmp_path, capsys):
    folder = _folder_with_files(tmp_path / "notarun")
    before = _snapshot(folder)
    rc, out, err = _cli(["report", str(folder)], capsys)
    assert (rc, out, err) == (2, "", f"recap: error: report: {folder} is not a run folder (no run.json)\n")
    assert _snapshot(folder) == before
    empty = tmp_path / "empty"
    empty.mkdir()
    rc, out, err = _cli(["report", str(empty), "--format", "md"], capsys)
    assert (rc, out, err) == (2, "", f"recap: error: report: {empty} is not a run folder (no run.json)\n")
    assert list(empty.iterdir()) == []


def test_report_refuses_an_output_folder_with_other_files(run, tmp_path, capsys):
    folder = _folder_with_files(tmp_path / "mine")
    before = _snapshot(folder)
    rc, out, err = _cli(["report", str(run), "--out", str(folder), "--format", "md"], capsys)
    assert (rc, out) == (2, "")
    assert err == (
        f"recap: error: report: output folder {folder} holds files a report did not write (such as {folder / 'episodes'}); "
        "give a new or empty folder with --out\n"
    )
    assert _snapshot(folder) == before
    # the run folder itself, and a file
    run_before = _snapshot(run)
    rc, _, err = _cli(["report", str(run), "--out", str(run), "--format", "md"], capsys)
    assert rc == 2 and err.startswith(f"recap: error: report: output folder {run} holds files a report did not write (such as ")
    rc, _, err = _cli(["report", str(run), "--out", str(run / "run.json"), "--format", "md"], capsys)
    assert (rc, err) == (2, f"recap: error: report: output folder {run / 'run.json'} is not a folder\n")
    assert _snapshot(run) == run_before
    rc, _, err = _cli(["report", str(run), "--out", "s3://bucket/report"], capsys)
    assert (rc, err) == (2, "recap: error: report: --out must be a local folder, got s3://bucket/report\n")


def test_report_refuses_a_report_folder_with_a_stranger_inside(run, tmp_path, capsys):
    out_dir = tmp_path / "rep"
    assert _cli(["report", str(run), "--out", str(out_dir), "--format", "md,csv"], capsys)[0] == 0
    assert _cli(["report", str(run), "--out", str(out_dir), "--format", "md,csv"], capsys)[0] == 0  # its own: fine
    (out_dir / "csv" / "notes.txt").write_text("mine")
    target = tmp_path / "elsewhere"
    target.mkdir()
    os.symlink(target, out_dir / "tex")
    before = _snapshot(out_dir)
    rc, out, err = _cli(["report", str(run), "--out", str(out_dir), "--format", "md,tex"], capsys)
    assert (rc, out) == (2, "")
    assert err.startswith(
        f"recap: error: report: output folder {out_dir} holds files a report did not write (such as {out_dir / 'csv' / 'notes.txt'})"
    )
    assert _snapshot(out_dir) == before and list(target.iterdir()) == []
    (out_dir / "csv" / "notes.txt").unlink()
    rc, _, err = _cli(["report", str(run), "--out", str(out_dir), "--format", "tex"], capsys)
    assert rc == 2 and f"(such as {out_dir / 'tex'})" in err and list(target.iterdir()) == []


def test_report_writes_only_under_its_output_folder(run, tmp_path, capsys):
    before = _snapshot(run)
    rc, out, err = _cli(["report", str(run), "--format", "md", "--title", "see https://example.org/x s3://b/y"], capsys)
    assert (rc, err) == (0, "")
    after = _snapshot(run)
    added = sorted(set(after) - set(before))
    assert added and all(p.startswith("report/") for p in added)
    assert {p: h for p, h in after.items() if p in before} == before
    assert "see https://example.org/x s3://b/y" in (run / "report" / "report.md").read_text()


def test_a_relative_run_folder_is_read_from_the_working_folder(run, capsys, monkeypatch):
    monkeypatch.chdir(run.parent)
    rc, out, err = _cli(["sql", run.name, "SELECT count(*) AS n FROM episodes", "--csv"], capsys)
    assert (rc, out, err) == (0, "n\n19\n", "")
