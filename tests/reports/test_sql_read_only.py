"""`recap sql` cannot write: every attack leaves every file of the run folder byte-identical,
exits 2 with one line on stderr, and reads nothing outside the run's views.

Two layers are tested separately:

* the connection itself (:func:`reports.views.open_runs`): DuckDB never holds a path to a part
  file (pyarrow reads them) and its file access is off and locked, so even statements sent
  straight to the raw connection - past the statement check - cannot touch a file;
* the command (`recap sql`, through the real CLI entry points): statements that are not queries
  are refused before they run, including EXPLAIN / EXPLAIN ANALYZE of anything but a query.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import duckdb
import pytest

from pipeline.cli import main as recap_main
from pipeline.cli.sql import sql_main
from reports.views import ReadOnlyError, check_read_only, open_runs, run_query
from schemas.parts import part_files

REPO = Path(__file__).resolve().parents[2]


def _snapshot(root: Path) -> dict[str, str]:
    """Every file and folder under ``root`` (hidden ones too) with a hash of its bytes."""
    out: dict[str, str] = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for d in dirnames:
            out[str(Path(dirpath, d).relative_to(root)) + "/"] = "dir"
        for f in filenames:
            p = Path(dirpath, f)
            out[str(p.relative_to(root))] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


@pytest.fixture
def run(run_a: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A fresh copy of run A, also the working folder (relative paths in attacks land in it)."""
    dest = tmp_path / "run"
    shutil.copytree(run_a, dest)
    monkeypatch.chdir(dest)
    return dest


def _fill(sql: str, run: Path) -> str:
    return sql.format(
        part=part_files(run, "episodes")[0],
        part2=part_files(run, "episodes")[1],
        calls=part_files(run, "llm_calls")[0],
        run=run,
    )


# Each is a statement (or script) that would write, change the connection's settings so that a
# later statement could write, or read a file outside the views. {part}, {part2}: episodes part
# files; {calls}: an llm_calls part file; {run}: the run folder.
ATTACKS = {
    "explain analyze copy over a part": "EXPLAIN ANALYZE COPY (SELECT 'x' AS a) TO '{part}' (FORMAT parquet, USE_TMP_FILE false)",
    "explain analyze copy, comment first": "/* hi */ EXPLAIN ANALYZE COPY (SELECT 'x' AS a) TO '{part}' (FORMAT parquet, USE_TMP_FILE false)",
    "explain analyze with options copy": "EXPLAIN ANALYZE (FORMAT json) COPY (SELECT 'x' AS a) TO '{part}' (FORMAT parquet, USE_TMP_FILE false)",
    "explain analyse lower case": "explain analyse copy (select 'x' as a) to '{part}' (format parquet, use_tmp_file false)",
    "explain copy": "EXPLAIN COPY (SELECT 'x' AS a) TO '{part}' (FORMAT parquet)",
    "explain analyze export": "EXPLAIN ANALYZE EXPORT DATABASE '{run}/dump'",
    "explain analyze create table as": "EXPLAIN ANALYZE CREATE TABLE t AS SELECT * FROM episodes",
    "explain analyze insert": "EXPLAIN ANALYZE INSERT INTO bad_parts VALUES ('a', 'b', 'c', 'd')",
    "explain analyze attach": "EXPLAIN ANALYZE ATTACH '{run}/new.db'",
    "copy select over a part": "COPY (SELECT 'x' AS a) TO '{part}' (FORMAT parquet, USE_TMP_FILE false)",
    "copy a view over its own part": "COPY (SELECT * FROM episodes) TO '{part}' (FORMAT parquet, USE_TMP_FILE false)",
    "copy a part into itself": "COPY (SELECT * FROM read_parquet('{part}')) TO '{part}' (FORMAT parquet, USE_TMP_FILE false)",
    "copy a part over another": "COPY (SELECT * FROM read_parquet('{part}')) TO '{part2}' (FORMAT parquet)",
    "copy table to": "COPY episodes TO '{part}' (FORMAT parquet)",
    "copy to a new file": "COPY (SELECT 1 AS a) TO '{run}/episodes/part-evil-000001.parquet' (FORMAT parquet)",
    "copy to a relative path": "COPY (SELECT 1 AS a) TO 'evil.csv'",
    "copy from a file into a table": "COPY bad_parts FROM '/etc/passwd'",
    "export database": "EXPORT DATABASE '{run}/dump'",
    "export database here": "EXPORT DATABASE 'dump' (FORMAT parquet)",
    "attach a new db in the run": "ATTACH '{run}/new.db' AS x",
    "attach then create": "ATTACH '{run}/new.db' AS x; CREATE TABLE x.t AS SELECT 1 AS a",
    "attach a part": "ATTACH '{part}' AS x",
    "set external access on then copy": "SET enable_external_access = true; COPY (SELECT 1 AS a) TO '{part}' (FORMAT parquet)",
    "reset external access": "RESET enable_external_access",
    "set allowed directories": "SET allowed_directories = ['{run}']",
    "set allowed paths then copy": "SET allowed_paths = ['{part}']; COPY (SELECT 1 AS a) TO '{part}' (FORMAT parquet)",
    "unlock configuration": "SET lock_configuration = false",
    "set temp directory into the run": "SET temp_directory = '{run}/episodes'",
    "pragma that sets profiling output": "PRAGMA enable_profiling = 'json'; PRAGMA profiling_output = '{part}'; SELECT count(*) FROM episodes",
    "set profiling output": "SET profiling_output = '{part}'",
    "pragma assignment of a read pragma name": "PRAGMA version = 1",
    "call enable_logging to a file": "CALL enable_logging(storage_path = '{run}/log')",
    "install": "INSTALL httpfs",
    "force install": "FORCE INSTALL httpfs",
    "load": "LOAD httpfs",
    "load a file": "LOAD '{part}'",
    "create table as": "CREATE TABLE t AS SELECT * FROM episodes",
    "create view": "CREATE VIEW v AS SELECT 1 AS a",
    "replace a view": "CREATE OR REPLACE VIEW episodes AS SELECT 1 AS a",
    "create persistent secret": "CREATE PERSISTENT SECRET s (TYPE s3, KEY_ID 'a', SECRET 'b')",
    "insert": "INSERT INTO bad_parts VALUES ('a', 'b', 'c', 'd')",
    "prepare copy": "PREPARE p AS COPY (SELECT 1 AS a) TO '{part}' (FORMAT parquet); EXECUTE p",
    "select then copy": "SELECT 1; COPY (SELECT 1 AS a) TO '{part}' (FORMAT parquet)",
    "select then explain analyze copy": "SELECT 1; EXPLAIN ANALYZE COPY (SELECT 1 AS a) TO '{part}' (FORMAT parquet)",
    "checkpoint": "CHECKPOINT",
    "vacuum": "VACUUM",
    "query() around a copy": "SELECT * FROM query('COPY (SELECT 1 AS a) TO ''{part}'' (FORMAT parquet)')",
    # reads outside the views: refused as well
    "read_csv /etc/passwd": "SELECT * FROM read_csv('/etc/passwd')",
    "read_text": "SELECT * FROM read_text('/etc/hostname')",
    "read_blob": "SELECT * FROM read_blob('/etc/passwd')",
    "glob": "SELECT * FROM glob('/etc/*')",
    "sniff_csv": "FROM sniff_csv('/etc/passwd')",
    "a file by name": "SELECT * FROM '/etc/passwd'",
    "a part file by path": "SELECT count(*) FROM read_parquet('{part}')",
    "parquet_metadata": "SELECT * FROM parquet_metadata('{part}')",
    "explain analyze a file read": "EXPLAIN ANALYZE SELECT * FROM read_csv('/etc/passwd')",
    "read_csv in a subquery": "SELECT (SELECT count(*) FROM read_csv('/etc/passwd')) AS n",
}


def _cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    rc = recap_main(argv)
    got = capsys.readouterr()
    return rc, got.out, got.err


@pytest.mark.parametrize("name", list(ATTACKS))
def test_attack_through_recap_sql_changes_nothing(name, run, capsys):
    before = _snapshot(run)
    rc, out, err = _cli(["sql", str(run), _fill(ATTACKS[name], run)], capsys)
    assert _snapshot(run) == before, name
    assert (rc, out) == (2, ""), (name, rc, out, err)
    assert len(err.splitlines()) == 1 and err.startswith("recap: error: sql: "), err


@pytest.mark.parametrize("name", list(ATTACKS))
def test_attack_from_a_query_file_changes_nothing(name, run, tmp_path, capsys):
    q = tmp_path / "attack.sql"
    q.write_text(_fill(ATTACKS[name], run))
    before = _snapshot(run)
    rc = sql_main([str(run), "--file", str(q)])
    out, err = capsys.readouterr()
    assert _snapshot(run) == before, name
    assert (rc, out) == (2, ""), (name, rc, out, err)
    assert len(err.splitlines()) == 1 and err.startswith("recap: error: sql: "), err


@pytest.mark.parametrize("name", list(ATTACKS))
def test_raw_connection_cannot_reach_any_file(name, run):
    """Past the statement check: the connection itself has no file it could write (or read)."""
    con = open_runs([run])
    before = _snapshot(run)
    sql = _fill(ATTACKS[name], run)
    try:
        statements = [st.query for st in con.extract_statements(sql)]
    except duckdb.ParserException:
        statements = [sql]  # DuckDB cannot parse it either; send it as it is
    for statement in statements:
        try:
            con.execute(statement).fetchall()
        except duckdb.Error:
            pass
    assert _snapshot(run) == before, name
    # the views still read the same rows (an in-memory CREATE OR REPLACE aside)
    if name != "replace a view":
        assert con.execute("SELECT count(*) FROM episodes").fetchall() == [(19,)]
    con.close()


def test_raw_connection_file_access_is_off_and_locked(run):
    con = open_runs([run])
    settings = dict(
        con.execute(
            "SELECT name, value FROM duckdb_settings() WHERE name IN ('enable_external_access', 'lock_configuration', "
            "'allowed_paths', 'allowed_directories', 'temp_directory')"
        ).fetchall()
    )
    assert settings == {
        "enable_external_access": "false",
        "lock_configuration": "true",
        "allowed_paths": "[]",
        "allowed_directories": "[]",
        "temp_directory": "",
    }
    part = part_files(run, "episodes")[0]
    for sql in (
        f"COPY (SELECT 1 AS a) TO '{part}' (FORMAT parquet, USE_TMP_FILE false)",
        f"SELECT count(*) FROM read_parquet('{part}')",
    ):
        with pytest.raises(duckdb.PermissionException):
            con.execute(sql)
    with pytest.raises(duckdb.InvalidInputException, match="configuration has been locked"):
        con.execute("SET enable_external_access = true")


READS = {
    "EXPLAIN SELECT count(*) FROM episodes": "physical_plan",
    "EXPLAIN ANALYZE SELECT count(*) FROM episodes": "analyzed_plan",
    "explain analyse select count(*) from episodes": "analyzed_plan",
    "/* c */ EXPLAIN ANALYZE (FORMAT json) SELECT count(*) FROM episodes": "analyzed_plan",
    "EXPLAIN (SELECT 1)": "physical_plan",
    "DESCRIBE episodes": "episode_id",
    "SUMMARIZE SELECT cost_usd FROM episodes": "cost_usd",
    "PRAGMA show_tables": "episodes",
    "PRAGMA table_info('episodes')": "episode_id",
    "WITH x AS (SELECT count(*) AS n FROM episodes) SELECT n FROM x": "19",
}


@pytest.mark.parametrize("sql", list(READS))
def test_queries_and_explain_of_queries_still_run(sql, run, capsys):
    before = _snapshot(run)
    rc, out, err = _cli(["sql", str(run), sql, "--json"], capsys)
    assert (rc, err) == (0, "")
    assert READS[sql] in out
    assert _snapshot(run) == before


@pytest.mark.parametrize(
    "sql,refused",
    [
        ("EXPLAIN ANALYZE COPY (SELECT 1) TO 'x.csv'", "refused EXPLAIN of a COPY statement"),
        ("EXPLAIN INSERT INTO bad_parts VALUES ('a', 'b', 'c', 'd')", "refused EXPLAIN of a INSERT statement"),
        ("EXPLAIN ANALYZE (FORMAT json) CREATE TABLE t AS SELECT 1", "refused EXPLAIN of a CREATE statement"),
        ("PRAGMA version = 1", "refused SET statement"),  # PRAGMA x = y is a SET
        ("PRAGMA enable_profiling", "refused PRAGMA statement"),
        ("FORCE INSTALL httpfs", "refused INSTALL statement"),
    ],
)
def test_refusal_messages(run, sql, refused):
    con = open_runs([run])
    with pytest.raises(ReadOnlyError) as err:
        check_read_only(con, sql)
    assert str(err.value).startswith(refused + ": reports are read-only (")
    assert run_query(con, "EXPLAIN ANALYZE SELECT 1").columns == ["explain_key", "explain_value"]


def test_attack_in_a_real_process(run):
    """`python -m pipeline.cli sql` as a process: exit 2, exactly one stderr line."""
    part = part_files(run, "episodes")[0]
    before = _snapshot(run)
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "pipeline.cli",
            "sql",
            str(run),
            f"EXPLAIN ANALYZE COPY (SELECT 'x' AS a) TO '{part}' (FORMAT parquet, USE_TMP_FILE false)",
        ],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert _snapshot(run) == before
    assert (proc.returncode, proc.stdout) == (2, "")
    assert proc.stderr.splitlines() == [
        "recap: error: sql: refused EXPLAIN of a COPY statement: reports are read-only "
        "(allowed: SELECT, WITH, DESCRIBE, SHOW, SUMMARIZE, EXPLAIN, read-only PRAGMA)"
    ]


# -- every recap sql error: one line, exit 2, a --file never echoed ---------------------------

SECRET = "sk-live-DO-NOT-ECHO-4242"


@pytest.mark.parametrize(
    "content",
    [
        f"api_key = {SECRET}\nsecond line\n".encode(),
        f"{SECRET}\n".encode(),
        f"SELECT '{SECRET}' FROM\n".encode(),
        f"# config\n[default]\naws_secret_access_key={SECRET}\n".encode(),
        b"\x89PNG\r\n\x1a\n\x00\x00" + SECRET.encode(),
        b"\xff\xfe" + SECRET.encode("utf-16-le"),
        SECRET.encode() + b"\xff\xff",
        b"",
        b"-- only a comment " + SECRET.encode() + b"\n",
    ],
)
def test_a_query_file_that_is_not_sql_is_one_line_exit_2_never_echoed(content, run, tmp_path, capsys):
    q = tmp_path / "not.sql"
    q.write_bytes(content)
    rc, out, err = _cli(["sql", str(run), "--file", str(q)], capsys)
    assert (rc, out) == (2, "")
    assert len(err.splitlines()) == 1 and err.startswith(f"recap: error: sql: query file {q} "), err
    assert SECRET not in err and "DO-NOT" not in err and "api_key" not in err


def test_query_file_errors(run, tmp_path, capsys):
    cases = {
        str(
            tmp_path / "missing.sql"
        ): f"recap: error: sql: cannot read query file {tmp_path / 'missing.sql'}: No such file or directory",
        str(tmp_path): f"recap: error: sql: cannot read query file {tmp_path}: Is a directory",
        "/dev/zero": "recap: error: sql: query file /dev/zero is larger than 1024 KiB; is it a query?",
    }
    for path, line in cases.items():
        rc, out, err = _cli(["sql", str(run), "--file", path], capsys)
        assert (rc, out, err) == (2, "", line + "\n")
    bad = tmp_path / "typo.sql"
    bad.write_text("SELECT count(*)\nFROM episodes\nWHER 1\n")
    rc, out, err = _cli(["sql", str(run), "--file", str(bad)], capsys)
    assert (rc, out, err) == (2, "", f"recap: error: sql: query file {bad} is not valid SQL (syntax error on line 3)\n")


@pytest.mark.parametrize(
    "argv,start",
    [
        (["SELEC 1"], "recap: error: sql: cannot parse query: Parser Error: syntax error"),
        (
            ["SELECT *\nFROM nosuch\nWHERE 1"],
            "recap: error: sql: query failed: Catalog Error: Table with name nosuch does not exist!",
        ),
        (["SELECT 1 +"], "recap: error: sql: cannot parse query: "),
        ([""], "recap: error: sql: empty query"),
        (["-- nothing"], "recap: error: sql: empty query"),
        (["@nosuch"], "recap: error: sql: no report query named 'nosuch'"),
        (["DROP VIEW episodes"], "recap: error: sql: refused DROP statement"),
        (["SELECT 1", "--max-rows", "x"], "recap: error: sql: argument --max-rows: invalid int value"),
        (["SELECT 1/0::int, 'a'::int"], "recap: error: sql: query failed: Conversion Error"),
    ],
)
def test_sql_errors_are_one_line_exit_2(argv, start, run, capsys):
    rc, out, err = _cli(["sql", str(run), *argv], capsys)
    assert (rc, out) == (2, "")
    assert len(err.splitlines()) == 1 and err.startswith(start), err
    assert "LINE " not in err


def test_missing_or_invalid_run_folder_is_exit_2(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    for folder, line in (
        (tmp_path / "missing", "does not exist or is not a folder"),
        (tmp_path / "empty", "is not a run folder"),
    ):
        rc = sql_main([str(folder), "SELECT 1"])
        out, err = capsys.readouterr()
        assert (rc, out) == (2, "") and len(err.splitlines()) == 1 and line in err, err


# -- resource attacks: memory and time limits -----------------------------------------------------

#: the limits the resource attacks run under (small, so that each stops within seconds)
ATTACK_MEMORY = "256MB"
ATTACK_MEMORY_BYTES = 256 * 1000**2
ATTACK_TIMEOUT_S = 2
#: the memory limit the time attacks run under: their memory is constant but not small - the child's
#: interpreter, DuckDB and pyarrow hold about 180 MB before the query starts, and a join's buffers
#: came to 238 MB on a loaded CI machine (over 256MB's stop threshold) - so they get room enough that
#: only the clock can stop them, and their peak must still stay under it
TIME_ATTACK_MEMORY = "512MB"
TIME_ATTACK_MEMORY_BYTES = 512 * 1000**2

#: queries that grow memory without bound (DuckDB's own memory_limit misses the scalar ones and the
#: conversion of a big result): each must stop at the memory limit
MEMORY_ATTACKS = {
    "list of 1e8 values": "SELECT list(i) FROM range(100000000) t(i)",
    "range() as one list value": "SELECT range(100000000)",
    "generate_series as one list value": "SELECT generate_series(1, 100000000)",
    "list_resize": "SELECT list_resize([1], 100000000)",
    "unnest of a huge list": "SELECT count(*) FROM (SELECT unnest(range(100000000)))",
    "repeat to 1 GB": "SELECT repeat('x', 1000000000)",
    "length of a 1 GB repeat": "SELECT length(repeat('x', 1000000000))",
    "concatenated repeats": "SELECT repeat('ab', 100000000) || repeat('cd', 100000000)",
    "string_agg of 1e8 numbers": "SELECT string_agg(i::VARCHAR, ',') FROM range(100000000) t(i)",
    "string_agg of repeats": "SELECT length(string_agg(repeat('x', 1000000), '')) FROM range(1000)",
    "recursive CTE doubling a string": (
        "WITH RECURSIVE r(n, s) AS (SELECT 1, 'x' UNION ALL SELECT n + 1, s || s FROM r WHERE n < 40) "
        "SELECT max(length(s)) FROM r"
    ),
    "huge sort": "SELECT i FROM range(100000000) t(i) ORDER BY random()",
    "count distinct of 1e8 strings": "SELECT count(DISTINCT i::VARCHAR) FROM range(100000000) t(i)",
    "a 2e7-row result": "SELECT * FROM range(20000000)",
    "cross join result": "SELECT a.range AS a, b.range AS b FROM range(100000) a, range(100000) b",
}

#: queries that run forever in constant memory: each must stop at the time limit
TIME_ATTACKS = {
    "cross join with a filter that never matches": (
        "SELECT count(*) FROM range(1000000) a, range(1000000) b WHERE a.range + b.range = -1"
    ),
    "count of 1e13 rows": "SELECT count(*) FROM range(10000000000000)",
    "md5 of 1e13 numbers": "SELECT max(md5(i::VARCHAR)) FROM range(10000000000000) t(i)",
}

_MEASURE = (
    "import json, resource, subprocess, sys; p = subprocess.run(sys.argv[1:], capture_output=True, text=True); "
    "print(json.dumps([p.returncode, p.stdout, p.stderr, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024]))"
)


def recap_measured(argv: list[str]) -> tuple[int, str, str, int]:
    """``python -m pipeline.cli ARGV`` as a process of its own: (exit status, stdout, stderr, peak RSS in
    bytes of the largest process in its tree - the CLI or its query process)."""
    import json

    env = dict(os.environ, PYTHONPATH=str(REPO), LITELLM_LOCAL_MODEL_COST_MAP="True", RAY_USAGE_STATS_ENABLED="0")
    proc = subprocess.run(
        [sys.executable, "-c", _MEASURE, sys.executable, "-m", "pipeline.cli", *argv],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    rc, out, err, peak = json.loads(proc.stdout)
    return rc, out, err, peak


MEMORY_LINE = f"recap: error: sql: memory limit {ATTACK_MEMORY} hit"
TIME_LINE = f"recap: error: sql: time limit {ATTACK_TIMEOUT_S}s hit: the query was stopped; raise it with --timeout\n"


@pytest.mark.parametrize("name", list(MEMORY_ATTACKS))
def test_memory_attack_stops_at_the_limit(name, run):
    before = _snapshot(run)
    rc, out, err, peak = recap_measured(["sql", str(run), MEMORY_ATTACKS[name], "--memory-limit", ATTACK_MEMORY])
    assert (rc, out) == (2, ""), (name, rc, out[:200], err)
    assert len(err.splitlines()) == 1 and err.startswith(MEMORY_LINE), err
    assert err.rstrip().endswith("raise it with --memory-limit, or select fewer rows or smaller values"), err
    assert peak < ATTACK_MEMORY_BYTES, (name, peak)
    assert _snapshot(run) == before


@pytest.mark.parametrize("name", list(TIME_ATTACKS))
def test_time_attack_stops_at_the_limit(name, run):
    rc, out, err, peak = recap_measured(
        ["sql", str(run), TIME_ATTACKS[name], "--timeout", str(ATTACK_TIMEOUT_S), "--memory-limit", TIME_ATTACK_MEMORY]
    )
    assert (rc, out, err) == (2, "", TIME_LINE), (name, peak)
    assert peak < TIME_ATTACK_MEMORY_BYTES, (name, peak)
