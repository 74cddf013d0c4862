"""Reading SWE-bench records: every bad input is one ValueError line naming file:line and the field."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from workers.envs.swe.examples import Fixtures
from workers.envs.swe.instances import DEFAULT_EVAL_TIMEOUT_S, DEFAULT_TEST_CMD, load_instances


def _records(fixtures: Fixtures) -> list[dict[str, Any]]:
    return [json.loads(line) for line in fixtures.tasks_file.read_text().splitlines()]


def _write(fixtures: Fixtures, tmp_path: Path, records: list[Any], raw_lines: list[str] | None = None) -> Path:
    """A tasks file beside the fixtures' (so relative repo paths resolve), with ``records``."""
    lines = [json.dumps(r) if not isinstance(r, str) else r for r in records] + (raw_lines or [])
    path = fixtures.tasks_file.parent / f"case-{tmp_path.name}.jsonl"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_fixture_records_load_in_file_order(fixtures: Fixtures) -> None:
    insts = load_instances(fixtures.tasks_file)
    assert [i.id for i in insts] == [
        "swe/fixture__offbyone-1",
        "swe/fixture__format-1",
        "swe/fixture__twofiles-1",
        "swe/fixture__newfunc-1",
        "swe/fixture__hang-1",
        "swe/fixture__p2p-1",
    ]
    two = insts[2]
    assert two.fail_to_pass == ("tests/test_convert.py::test_inches_to_cm", "tests/test_convert.py::test_cm_to_inches")
    assert two.pass_to_pass == ("tests/test_convert.py::test_zero",)
    assert two.repo_path == str((fixtures.tasks_file.parent / "repos" / "twofiles").resolve())
    assert two.extra == {"version": "0.1"}
    assert two.eval_timeout_s == DEFAULT_EVAL_TIMEOUT_S
    assert insts[4].eval_timeout_s == 10.0


def test_lists_may_be_plain_lists_and_defaults_apply(fixtures: Fixtures, tmp_path: Path) -> None:
    rec = _records(fixtures)[0]
    rec["FAIL_TO_PASS"] = json.loads(rec["FAIL_TO_PASS"])
    rec["PASS_TO_PASS"] = []
    del rec["test_cmd"]
    (inst,) = load_instances(_write(fixtures, tmp_path, [rec]))
    assert inst.fail_to_pass == ("tests/test_mathutil.py::test_count_range_inclusive",)
    assert inst.pass_to_pass == ()
    assert inst.test_cmd == DEFAULT_TEST_CMD


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda r: r.pop("base_commit"), "missing field 'base_commit'"),
        (lambda r: r.pop("FAIL_TO_PASS"), "missing field 'FAIL_TO_PASS'"),
        (
            lambda r: r.update(FAIL_TO_PASS="[]"),
            "field 'FAIL_TO_PASS' is empty (a task needs at least one test that the fix makes pass)",
        ),
        (lambda r: r.update(FAIL_TO_PASS="[tests/x.py::t"), "field 'FAIL_TO_PASS' is not a JSON-encoded list (Expecting value)"),
        (
            lambda r: r.update(PASS_TO_PASS='{"a": 1}'),
            "field 'PASS_TO_PASS' must be a list of pytest node ids (non-empty strings)",
        ),
        (lambda r: r.update(PASS_TO_PASS=[1]), "field 'PASS_TO_PASS' must be a list of pytest node ids (non-empty strings)"),
        (lambda r: r.update(patch=None), "field 'patch' must be a string, got NoneType"),
        (lambda r: r.update(instance_id="a b"), "field 'instance_id' must not contain whitespace, got 'a b'"),
        (lambda r: r.update(problem_statement="  "), "field 'problem_statement' is empty"),
        (lambda r: r.update(test_cmd=""), "field 'test_cmd' must be a non-empty string, got ''"),
        (lambda r: r.update(eval_timeout_s=0), "field 'eval_timeout_s' must be a positive number of seconds, got 0"),
    ],
)
def test_bad_field_is_one_line_naming_file_line_and_field(fixtures: Fixtures, tmp_path: Path, change: Any, message: str) -> None:
    good, bad = _records(fixtures)[:2]
    change(bad)
    path = _write(fixtures, tmp_path, [good, bad])
    with pytest.raises(ValueError) as err:
        load_instances(path)
    assert str(err.value) == f"{path}:2: {message}"


def test_repo_path_that_is_not_a_git_repository(fixtures: Fixtures, tmp_path: Path) -> None:
    rec = _records(fixtures)[0]
    rec["repo_path"] = str(tmp_path)
    path = _write(fixtures, tmp_path, [rec])
    with pytest.raises(ValueError) as err:
        load_instances(path)
    assert str(err.value) == f"{path}:1: field 'repo_path': {tmp_path} is not a git repository"


def test_base_commit_the_repository_lacks(fixtures: Fixtures, tmp_path: Path) -> None:
    good, bad = _records(fixtures)[:2]
    bad["base_commit"] = "0" * 40
    path = _write(fixtures, tmp_path, [good, bad])
    with pytest.raises(ValueError) as err:
        load_instances(path)
    repo = (fixtures.tasks_file.parent / "repos" / "format").resolve()
    assert str(err.value) == f"{path}:2: field 'base_commit': {'0' * 40} is not a commit of {repo}"


def test_bad_json_duplicate_id_and_non_object(fixtures: Fixtures, tmp_path: Path) -> None:
    rec = _records(fixtures)[0]
    path = _write(fixtures, tmp_path, [rec], ["{not json"])
    with pytest.raises(ValueError) as err:
        load_instances(path)
    assert str(err.value) == f"{path}:2: not valid JSON (Expecting property name enclosed in double quotes at column 2)"
    path = _write(fixtures, tmp_path, [rec, "", rec])
    with pytest.raises(ValueError) as err:
        load_instances(path)
    assert str(err.value) == f"{path}:3: field 'instance_id': duplicate id 'fixture__offbyone-1' (first on line 1)"
    path = _write(fixtures, tmp_path, ["[1, 2]"])
    with pytest.raises(ValueError) as err:
        load_instances(path)
    assert str(err.value) == f"{path}:1: a record must be a JSON object, got list"


def test_missing_and_empty_files(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError) as missing:
        load_instances(tmp_path / "nope.jsonl")
    assert str(missing.value) == f"SWE-bench instances file {tmp_path / 'nope.jsonl'} does not exist"
    empty = tmp_path / "empty.jsonl"
    empty.write_text("\n\n")
    with pytest.raises(ValueError) as err:
        load_instances(empty)
    assert str(err.value) == f"{empty}: holds no SWE-bench records"
