"""open_runs: the views and their schemas, unreadable part files, read-only refusals, bad input."""

from __future__ import annotations

import shutil
from pathlib import Path

import duckdb
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from reports.views import (
    ReadOnlyError,
    RunDirError,
    check_read_only,
    duckdb_types,
    named_query,
    open_runs,
    open_runs_checked,
    run_query,
)
from schemas.parts import part_files
from schemas.tables import TABLES

NAMED_VIEWS = [
    "attempts",
    "terminal",
    "outcomes",
    "calls",
    "nodes",
    "tree_stats",
    "step_patterns",
    "tool_stats",
    "episode_modes",
    "failures",
]


def _columns(con, name: str) -> list[tuple[str, str]]:
    return [(r[0], r[1]) for r in con.execute(f'DESCRIBE "{name}"').fetchall()]


def test_one_view_per_table_with_the_declared_schema(run_a):
    con = open_runs([run_a])
    for table, schema in TABLES.items():
        assert [c for c, _ in _columns(con, table)] == schema.names
        assert dict(_columns(con, table)) == duckdb_types()[table]
    assert run_query(con, "SELECT count(*) FROM messages").rows == [(9,)]
    for view in NAMED_VIEWS:
        run_query(con, f"SELECT * FROM {view} LIMIT 1")


def test_empty_tables_are_empty_views_with_the_schema(tmp_path):
    (tmp_path / "run.json").write_text("{}")
    con = open_runs([tmp_path])
    for table in TABLES:
        assert dict(_columns(con, table)) == duckdb_types()[table]
        assert run_query(con, f'SELECT count(*) FROM "{table}"').rows == [(0,)]
    for view in NAMED_VIEWS:
        assert run_query(con, f"SELECT count(*) FROM {view}").rows == [(0,)]
    assert named_query(con, "overview").rows == [(1, 0, 0, 0, 0, 0, 0, 0, 0.0, 0, 0)]


def _copy_run(run_a: Path, dest: Path) -> Path:
    shutil.copytree(run_a, dest)
    return dest


def test_corrupt_part_file_is_skipped_and_reported(run_a, tmp_path):
    run = _copy_run(run_a, tmp_path / "run")
    parts = part_files(run, "episodes")
    assert len(parts) == 2
    # cut the second episodes file (episodes 9..19 of run A) in half: a truncated write
    data = parts[1].read_bytes()
    parts[1].write_bytes(data[: len(data) // 2])
    (run / "messages" / "part-zzzz-000001.parquet").write_bytes(b"not parquet at all")
    con, skipped = open_runs_checked([run])
    assert sorted((s.table, Path(s.path).name) for s in skipped) == [
        ("episodes", parts[1].name),
        ("messages", "part-zzzz-000001.parquet"),
    ]
    assert all(s.error for s in skipped)
    assert run_query(con, 'SELECT "table", path FROM bad_parts ORDER BY path').rows == [
        ("episodes", str(parts[1])),
        ("messages", str(run / "messages" / "part-zzzz-000001.parquet")),
    ]
    # the first 8 episode rows remain (the first 8 of RUN_A_EPISODES), all messages remain
    assert run_query(con, "SELECT count(*) FROM episodes").rows == [(8,)]
    assert run_query(con, "SELECT count(*) FROM messages").rows == [(9,)]
    assert named_query(con, "overview").dicts()[0]["skipped_part_files"] == 2


def test_table_whose_only_file_is_corrupt_is_empty(run_a, tmp_path):
    run = _copy_run(run_a, tmp_path / "run")
    for p in part_files(run, "steps"):
        p.write_bytes(b"PAR1garbagePAR1")
    con, skipped = open_runs_checked([run])
    assert [s.table for s in skipped] == ["steps"]
    assert run_query(con, "SELECT count(*) FROM steps").rows == [(0,)]
    assert dict(_columns(con, "steps")) == duckdb_types()["steps"]
    # without steps no loop is detected: t2/84 attempt 2 is a plain step_cap now
    assert run_query(con, "SELECT mode FROM episode_modes WHERE episode_id = 'A-react-t2-84-a2'").rows == [("step_cap",)]


def test_part_missing_a_column_is_skipped_and_named(tmp_path):
    """A part without every column of its table (a foreign file, a run of another schema
    version) is skipped and named, as ``recap status`` and resume do; the view keeps every
    column. (Rule: schemas.parts.schema_problem - exact column names and Arrow types.)"""
    schema = TABLES["episodes"]
    old = pa.schema([f for f in schema if f.name not in ("test_double", "worker_id")])
    row = {f.name: None for f in old}
    row.update(
        run_id="old",
        episode_id="e1",
        unit_id="u1",
        attempt=1,
        benchmark="robotouille",
        split="synchronous",
        task="t1",
        instance_id="i1",
        sampling_seed=42,
        method="react",
        method_config="{}",
        model="gpt-4o",
        end_reason="success",
        success=True,
        steps=3,
        llm_calls=2,
        prompt_tokens=10,
        cached_prompt_tokens=0,
        completion_tokens=5,
        cost_usd=0.5,
        wall_s=1.0,
        step_cap=40,
        step_multiplier=4.0,
        max_depth=0,
        started_at=1.0,
        ended_at=2.0,
        label="react",
    )
    (tmp_path / "episodes").mkdir()
    part = tmp_path / "episodes" / "part-old-000001.parquet"
    pq.write_table(pa.Table.from_pylist([row], schema=old), part)
    (tmp_path / "run.json").write_text('{"run_id": "old"}')
    con, skipped = open_runs_checked([tmp_path])
    assert [(s.table, s.path, s.error) for s in skipped] == [
        ("episodes", str(part), "ValueError: not a episodes part: missing column(s) test_double, worker_id")
    ]
    assert [c for c, _ in _columns(con, "episodes")] == schema.names
    assert run_query(con, "SELECT count(*) FROM terminal").rows == [(0,)]
    assert run_query(con, "SELECT path FROM bad_parts").rows == [(str(part),)]


# -- read-only -------------------------------------------------------------------------------

REFUSED = {
    "CREATE TABLE x AS SELECT 1": "refused CREATE statement",
    "INSERT INTO bad_parts VALUES ('a', 'b', 'c', 'd')": "refused INSERT statement",
    "DELETE FROM bad_parts": "refused DELETE statement",
    "UPDATE bad_parts SET path = 'x'": "refused UPDATE statement",
    "DROP VIEW episodes": "refused DROP statement",
    "COPY (SELECT 1) TO 'out.csv'": "refused COPY statement",
    "EXPORT DATABASE 'dump'": "refused EXPORT statement",
    "ATTACH 'other.db'": "refused ATTACH statement",
    "SET threads = 1": "refused SET statement",
    "INSTALL httpfs": "refused INSTALL statement",
    "LOAD httpfs": "refused LOAD statement",
    "PRAGMA enable_profiling": "refused PRAGMA statement",
    "SELECT 1; DROP VIEW episodes": "refused DROP statement",
    "CALL pragma_version()": "refused CALL statement",
}


@pytest.mark.parametrize("sql", list(REFUSED))
def test_statements_that_write_are_refused(run_a, sql):
    con = open_runs([run_a])
    with pytest.raises(ReadOnlyError) as err:
        run_query(con, sql)
    assert str(err.value) == (
        f"{REFUSED[sql]}: reports are read-only (allowed: SELECT, WITH, DESCRIBE, SHOW, SUMMARIZE, EXPLAIN, read-only PRAGMA)"
    )
    assert run_query(con, "SELECT count(*) FROM episodes").rows == [(19,)]


@pytest.mark.parametrize(
    "sql",
    [
        "SELECT 1",
        "WITH a AS (SELECT 2) SELECT * FROM a",
        "FROM episodes LIMIT 1",
        "DESCRIBE episodes",
        "SHOW TABLES",
        "SUMMARIZE steps",
        "EXPLAIN SELECT * FROM terminal",
        "PRAGMA table_info('episodes')",
        "VALUES (1), (2)",
    ],
)
def test_queries_are_allowed(run_a, sql):
    con = open_runs([run_a])
    assert check_read_only(con, sql) == 1
    run_query(con, sql)


def test_raw_connection_cannot_touch_other_files(run_a, tmp_path):
    """Even statements sent around run_query: no file outside the run's part files."""
    con = open_runs([run_a])
    target = tmp_path / "out.csv"
    for sql in (
        f"COPY (SELECT 1) TO '{target}'",
        f"COPY (SELECT 1) TO '{run_a / 'episodes' / 'new.parquet'}'",
        f"ATTACH '{tmp_path / 'x.db'}' AS x",
        "SELECT * FROM read_csv('/etc/passwd')",
        f"SELECT * FROM read_parquet('{run_a}/*/*.parquet')",
    ):
        with pytest.raises(duckdb.PermissionException):
            con.execute(sql)
    with pytest.raises(duckdb.Error, match="lock"):
        con.execute("SET enable_external_access = true")
    assert not target.exists()
    assert not (run_a / "episodes" / "new.parquet").exists()


def test_bad_run_folders(tmp_path):
    with pytest.raises(RunDirError) as err:
        open_runs([tmp_path / "nope"])
    assert str(err.value) == f"run folder {tmp_path / 'nope'} does not exist or is not a folder"
    (tmp_path / "empty").mkdir()
    with pytest.raises(RunDirError) as err:
        open_runs([tmp_path / "empty"])
    assert str(err.value) == f"{tmp_path / 'empty'} is not a run folder (no run.json)"
    # table folders alone do not make a run folder (recap status and resume refuse it too)
    (tmp_path / "tables" / "episodes").mkdir(parents=True)
    with pytest.raises(RunDirError) as err:
        open_runs([tmp_path / "tables"])
    assert str(err.value) == f"{tmp_path / 'tables'} is not a run folder (no run.json)"
    (tmp_path / "tables" / "run.json").write_text("[1, 2]")
    with pytest.raises(RunDirError) as err:
        open_runs([tmp_path / "tables"])
    assert str(err.value) == f"{tmp_path / 'tables'} is not a run folder (its run.json is unreadable or not a JSON object)"
    with pytest.raises(RunDirError, match="no run folder given"):
        open_runs([])


def test_syntax_error_is_one_line(run_a):
    con = open_runs([run_a])
    with pytest.raises(Exception) as err:
        run_query(con, "SELEC 1")
    assert str(err.value).startswith('cannot parse query: Parser Error: syntax error at or near "SELEC"')
    assert "\n" not in str(err.value)
