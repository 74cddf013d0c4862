"""SWE-bench task records: read a JSONL file of SWE-bench-shaped records into :class:`SweInstance`.

One record per line, the SWE-bench dataset's fields (``instance_id``, ``repo``, ``base_commit``,
``problem_statement``, ``patch``, ``test_patch``, ``FAIL_TO_PASS``, ``PASS_TO_PASS``; the two test
lists JSON-encoded strings as the dataset ships them, or plain lists) plus ``repo_path``: a local
git repository holding ``base_commit`` (no network is used to fetch one; relative paths are read
from the JSONL file's folder). Optional: ``test_cmd`` (default ``python -m pytest -q``) and
``eval_timeout_s`` (the evaluation's test run; default :data:`DEFAULT_EVAL_TIMEOUT_S`, the
SWE-bench harness's 30 minutes). Every other field is kept in ``extra``. Every bad input is one
``ValueError`` line naming ``file:line`` and the field, before anything runs.

The file is a user's, so it is read with bounds (:mod:`workers.envs.user_json`: a line at a time,
each under 16 MiB, nesting checked before parsing) and each record's fields with limits of their
own, because they reach paths, commands and prompts: ``instance_id`` is letters, digits, ``_``,
``.``, ``-`` (no ``/``, no ``..``, no shell metacharacter; at most :data:`MAX_ID_CHARS`: it names
containers, folders and files); ``repo_path`` is a git repository that is not ``/``, the home
folder or a folder above it (the whole of it would be cloned into every sandbox); the gold
``patch`` and the ``test_patch`` write only inside the repository (:mod:`.patch_paths`); the
``problem_statement`` is at most :data:`MAX_PROBLEM_BYTES` (it is sent to the model on every call).
"""

from __future__ import annotations

import json
import re
import subprocess
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from workers.envs import user_json

from .patch_paths import patch_refusal

#: the registry name, the first part of every instance id
BENCHMARK_NAME = "swe"
DEFAULT_TEST_CMD = "python -m pytest -q"
#: the SWE-bench harness's per-instance test timeout (swebench/harness/run_evaluation.py: 1800 s)
DEFAULT_EVAL_TIMEOUT_S = 1800.0
#: string fields every record must carry
REQUIRED_TEXT = ("instance_id", "repo", "base_commit", "problem_statement", "patch", "test_patch", "repo_path")
#: the test lists, JSON-encoded strings (SWE-bench) or lists
TEST_LISTS = ("FAIL_TO_PASS", "PASS_TO_PASS")
OPTIONAL = ("test_cmd", "eval_timeout_s")
#: the longest instance id (SWE-bench's own, ``owner__repo-NUMBER``, are under 50 characters)
MAX_ID_CHARS = 128
#: an instance id's characters: it names containers, image tags, folders and files
SAFE_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")
#: the largest problem statement, in UTF-8 bytes (SWE-bench Verified's largest is a few tens of kB)
MAX_PROBLEM_BYTES = 1 << 20


def id_problem(iid: str) -> str | None:
    """Why ``iid`` cannot be an instance id (one phrase), or None: whitespace, a character outside
    :data:`SAFE_ID` (``/``, a shell metacharacter), ``..``, or more than :data:`MAX_ID_CHARS`."""
    if len(iid) > MAX_ID_CHARS:
        return f"is {len(iid)} characters long, more than {MAX_ID_CHARS}"
    if iid != iid.strip() or any(c.isspace() for c in iid):
        return f"must not contain whitespace, got {iid!r}"
    if SAFE_ID.fullmatch(iid) is None or ".." in iid:
        return f"must be letters, digits, '_', '.' and '-' (starting with a letter or digit, no '..'), got {iid!r}"
    return None


def problem_size_problem(text: str) -> str | None:
    """Why a problem statement is too large (its size and the cap), or None."""
    size = len(text.encode("utf-8", errors="surrogatepass"))
    if size > MAX_PROBLEM_BYTES:
        return f"is {size} bytes, more than the {MAX_PROBLEM_BYTES} a problem statement may hold"
    return None


def repo_path_problem(path: Path) -> str | None:
    """Why ``path`` (resolved) cannot be a task's repository, or None: ``/``, the home folder or
    a folder above it (each would put a whole tree of this host into the sandboxes)."""
    home = Path.home().resolve()
    if path == Path(path.anchor):
        return f"{path} is the root folder"
    if path == home or path in home.parents:
        return f"{path} is the home folder or above it"
    return None


@dataclass(frozen=True)
class SweInstance:
    """One SWE-bench task: the repository at ``base_commit``, the issue text, the tests that must
    go from failing to passing (``fail_to_pass``) and those that must keep passing
    (``pass_to_pass``), the gold ``patch`` and the ``test_patch`` the evaluation applies."""

    instance_id: str
    repo: str
    base_commit: str
    problem_statement: str
    fail_to_pass: tuple[str, ...]
    pass_to_pass: tuple[str, ...]
    patch: str
    test_patch: str
    repo_path: str
    test_cmd: str = DEFAULT_TEST_CMD
    eval_timeout_s: float = DEFAULT_EVAL_TIMEOUT_S
    #: the record's other fields (version, created_at, hints_text, environment_setup_commit...)
    extra: Mapping[str, Any] = field(default_factory=dict)

    @property
    def id(self) -> str:
        """The registry id, ``swe/<instance_id>``."""
        return f"{BENCHMARK_NAME}/{self.instance_id}"


def _test_list(where: str, name: str, value: Any) -> tuple[str, ...]:
    if isinstance(value, str):
        try:
            value = user_json.loads(value)
        except json.JSONDecodeError as exc:
            raise ValueError(f"{where}: field {name!r} is not a JSON-encoded list ({exc.msg})") from None
        except ValueError as exc:
            raise ValueError(f"{where}: field {name!r}: {exc}") from None
    if not isinstance(value, list) or not all(isinstance(t, str) and t.strip() for t in value):
        raise ValueError(f"{where}: field {name!r} must be a list of pytest node ids (non-empty strings)")
    return tuple(value)


def is_git_repo(path: Path) -> bool:
    """Whether ``path`` is a git work tree or a bare repository (by its layout, no process)."""
    return (path / ".git").exists() or ((path / "HEAD").is_file() and (path / "objects").is_dir())


def parse_record(raw: Any, where: str, base: Path) -> SweInstance:
    """One record (already JSON-decoded) as a :class:`SweInstance`; ValueError naming ``where`` and the field."""
    if not isinstance(raw, dict):
        raise ValueError(f"{where}: a record must be a JSON object, got {type(raw).__name__}")
    for name in (*REQUIRED_TEXT, *TEST_LISTS):
        if name not in raw:
            raise ValueError(f"{where}: missing field {name!r}")
    for name in REQUIRED_TEXT:
        if not isinstance(raw[name], str):
            raise ValueError(f"{where}: field {name!r} must be a string, got {type(raw[name]).__name__}")
    for name in ("instance_id", "repo", "base_commit", "problem_statement", "repo_path"):
        if not raw[name].strip():
            raise ValueError(f"{where}: field {name!r} is empty")
    iid = raw["instance_id"]
    if (problem := id_problem(iid)) is not None:
        raise ValueError(f"{where}: field 'instance_id' {problem}")
    if (problem := problem_size_problem(raw["problem_statement"])) is not None:
        raise ValueError(f"{where}: field 'problem_statement' {problem}")
    for name in ("patch", "test_patch"):
        if (problem := patch_refusal(raw[name])) is not None:
            raise ValueError(f"{where}: field {name!r}: {problem}")
    f2p = _test_list(where, "FAIL_TO_PASS", raw["FAIL_TO_PASS"])
    p2p = _test_list(where, "PASS_TO_PASS", raw["PASS_TO_PASS"])
    if not f2p:
        raise ValueError(f"{where}: field 'FAIL_TO_PASS' is empty (a task needs at least one test that the fix makes pass)")
    repo_path = Path(raw["repo_path"]).expanduser()
    if not repo_path.is_absolute():
        repo_path = base / repo_path
    if (problem := repo_path_problem(repo_path.resolve())) is not None:
        raise ValueError(f"{where}: field 'repo_path': {problem}, not a task's repository")
    if not is_git_repo(repo_path):
        raise ValueError(f"{where}: field 'repo_path': {repo_path} is not a git repository")
    test_cmd = raw.get("test_cmd", DEFAULT_TEST_CMD)
    if not isinstance(test_cmd, str) or not test_cmd.strip():
        raise ValueError(f"{where}: field 'test_cmd' must be a non-empty string, got {test_cmd!r}")
    timeout = raw.get("eval_timeout_s", DEFAULT_EVAL_TIMEOUT_S)
    if isinstance(timeout, bool) or not isinstance(timeout, (int, float)) or not timeout > 0:
        raise ValueError(f"{where}: field 'eval_timeout_s' must be a positive number of seconds, got {timeout!r}")
    known = {*REQUIRED_TEXT, *TEST_LISTS, *OPTIONAL}
    return SweInstance(
        instance_id=iid,
        repo=raw["repo"],
        base_commit=raw["base_commit"].strip(),
        problem_statement=raw["problem_statement"],
        fail_to_pass=f2p,
        pass_to_pass=p2p,
        patch=raw["patch"],
        test_patch=raw["test_patch"],
        repo_path=str(repo_path.resolve()),
        test_cmd=test_cmd.strip(),
        eval_timeout_s=float(timeout),
        extra={k: v for k, v in raw.items() if k not in known},
    )


def missing_commits(repo_path: str, commits: list[str]) -> list[str]:
    """The ``commits`` that ``repo_path`` does not hold (one ``git cat-file --batch-check``)."""
    proc = subprocess.run(
        ["git", "-C", repo_path, "cat-file", "--batch-check"],
        input="".join(f"{c}^{{commit}}\n" for c in commits),
        capture_output=True,
        text=True,
        check=False,
    )
    lines = proc.stdout.splitlines()
    if proc.returncode != 0 or len(lines) != len(commits):
        return list(commits)
    return [c for c, line in zip(commits, lines) if line.endswith(" missing") or not line.split(" ")[1:2] == ["commit"]]


def _records(file: Path) -> Iterator[tuple[int, Any]]:
    """``(line number, decoded JSON)`` of each non-blank line, read a line at a time with the
    bounds of :mod:`workers.envs.user_json`; ValueError ``file:line: ...`` otherwise."""
    try:
        f = file.open("rb")
    except FileNotFoundError:
        raise FileNotFoundError(f"SWE-bench instances file {file} does not exist") from None
    except OSError as exc:
        raise ValueError(f"{file}: cannot be read ({exc.strerror or exc})") from None
    with f:
        yield from user_json.records(f, str(file))


def load_instances(path: str | Path) -> list[SweInstance]:
    """Every record of the JSONL file ``path`` in file order (blank lines skipped); ValueError
    ``file:line: ...`` for a missing or bad field, bad JSON, a duplicate id, a ``repo_path`` that
    is not a git repository or lacks the record's ``base_commit``; FileNotFoundError for no file."""
    file = Path(path).expanduser()
    out: list[SweInstance] = []
    lines: dict[str, int] = {}
    for lineno, raw in _records(file):
        where = f"{file}:{lineno}"
        inst = parse_record(raw, where, file.parent)
        if inst.instance_id in lines:
            raise ValueError(
                f"{where}: field 'instance_id': duplicate id {inst.instance_id!r} (first on line {lines[inst.instance_id]})"
            )
        lines[inst.instance_id] = lineno
        out.append(inst)
    if not out:
        raise ValueError(f"{file}: holds no SWE-bench records")
    by_repo: dict[str, list[SweInstance]] = {}
    for inst in out:
        by_repo.setdefault(inst.repo_path, []).append(inst)
    for repo_path, insts in by_repo.items():
        missing = set(missing_commits(repo_path, [i.base_commit for i in insts]))
        for inst in insts:
            if inst.base_commit in missing:
                raise ValueError(
                    f"{file}:{lines[inst.instance_id]}: field 'base_commit': {inst.base_commit} is not a commit of {repo_path}"
                )
    return out
