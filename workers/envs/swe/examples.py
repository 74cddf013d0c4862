"""Six tiny SWE-bench-shaped example tasks, built on demand: git repositories plus ``tasks.jsonl``.

Why in the package: the demo, the benches and the tests all run coding episodes on them, and a
user can see the record format they need for their own tasks
(``python -m workers.envs.swe.examples DIR`` writes them into ``DIR``; a sweep then names
``DIR/tasks.jsonl`` as ``instances_file``). :func:`make_fixtures` creates them in a given folder.
Each repository's ``main`` is its base commit, with
the tests that already pass; the record's ``test_patch`` adds the failing ones and ``patch`` is the
gold fix (both real ``git diff`` output). ``WRONG`` patches, per task, are for the evaluator's tests.

- ``offbyone``: a range that leaves out its end;
- ``format``: a price printed without two decimals;
- ``twofiles``: a fix that needs two files (a constant and a formula);
- ``newfunc``: the issue asks for a new function;
- ``hang``: a binary search that loops forever on some inputs; its evaluation timeout is small;
- ``p2p``: tests that already pass and that a sloppy fix breaks.
"""

from __future__ import annotations

import json
import subprocess
from dataclasses import dataclass
from pathlib import Path

#: plugins off: the tests need none, and loading the installed ones is most of a run's time
TEST_CMD = "PYTEST_DISABLE_PLUGIN_AUTOLOAD=1 python -m pytest -q -p no:cacheprovider"
#: the ``hang`` task's evaluation timeout (a wrong patch's test run is stopped after this)
HANG_TIMEOUT_S = 10.0
GITIGNORE = "__pycache__/\n*.pyc\n.pytest_cache/\n"


@dataclass(frozen=True)
class Task:
    """One fixture: files at the base commit, the gold fix's files, the new tests' files, the issue."""

    name: str
    problem: str
    base: dict[str, str]
    gold: dict[str, str]
    tests: dict[str, str]
    fail_to_pass: tuple[str, ...]
    pass_to_pass: tuple[str, ...]
    wrong: dict[str, str] | None = None
    eval_timeout_s: float | None = None


TASKS: tuple[Task, ...] = (
    Task(
        "offbyone",
        "count_range(a, b) should include b: count_range(1, 3) must be [1, 2, 3] but it returns [1, 2].",
        {
            "mathutil.py": 'def count_range(a, b):\n    """The integers from a to b, both included."""\n    return list(range(a, b))\n\n\ndef total(xs):\n    return sum(xs)\n',
            "tests/test_mathutil.py": "from mathutil import total\n\n\ndef test_total():\n    assert total([1, 2]) == 3\n",
        },
        {
            "mathutil.py": 'def count_range(a, b):\n    """The integers from a to b, both included."""\n    return list(range(a, b + 1))\n\n\ndef total(xs):\n    return sum(xs)\n'
        },
        {
            "tests/test_mathutil.py": "from mathutil import count_range, total\n\n\ndef test_total():\n    assert total([1, 2]) == 3\n\n\ndef test_count_range_inclusive():\n    assert count_range(1, 3) == [1, 2, 3]\n"
        },
        ("tests/test_mathutil.py::test_count_range_inclusive",),
        ("tests/test_mathutil.py::test_total",),
    ),
    Task(
        "format",
        'format_price(350) returns "$3.5"; prices must always show two decimals ("$3.50").',
        {
            "shop.py": 'def format_price(cents):\n    return f"${cents / 100}"\n\n\ndef format_count(n):\n    return f"{n} items"\n',
            "tests/test_shop.py": 'from shop import format_count\n\n\ndef test_count():\n    assert format_count(2) == "2 items"\n',
        },
        {
            "shop.py": 'def format_price(cents):\n    return f"${cents / 100:.2f}"\n\n\ndef format_count(n):\n    return f"{n} items"\n'
        },
        {
            "tests/test_shop.py": 'from shop import format_count, format_price\n\n\ndef test_count():\n    assert format_count(2) == "2 items"\n\n\ndef test_price_two_decimals():\n    assert format_price(350) == "$3.50"\n'
        },
        ("tests/test_shop.py::test_price_two_decimals",),
        ("tests/test_shop.py::test_count",),
        wrong={
            "shop.py": 'def format_price(cents):\n    return f"${cents / 100:.1f}"\n\n\ndef format_count(n):\n    return f"{n} items"\n'
        },
    ),
    Task(
        "twofiles",
        "Unit conversion is wrong both ways: inches_to_cm(1) gives 2.45 (should be 2.54) and cm_to_inches(2.54) does not give 1.",
        {
            "units.py": "CM_PER_INCH = 2.45\n",
            "convert.py": "from units import CM_PER_INCH\n\n\ndef inches_to_cm(x):\n    return x * CM_PER_INCH\n\n\ndef cm_to_inches(x):\n    return x * CM_PER_INCH\n",
            "tests/test_convert.py": "from convert import inches_to_cm\n\n\ndef test_zero():\n    assert inches_to_cm(0) == 0\n",
        },
        {
            "units.py": "CM_PER_INCH = 2.54\n",
            "convert.py": "from units import CM_PER_INCH\n\n\ndef inches_to_cm(x):\n    return x * CM_PER_INCH\n\n\ndef cm_to_inches(x):\n    return x / CM_PER_INCH\n",
        },
        {
            "tests/test_convert.py": "from convert import cm_to_inches, inches_to_cm\n\n\ndef test_zero():\n    assert inches_to_cm(0) == 0\n\n\ndef test_inches_to_cm():\n    assert abs(inches_to_cm(1) - 2.54) < 1e-9\n\n\ndef test_cm_to_inches():\n    assert abs(cm_to_inches(2.54) - 1) < 1e-9\n"
        },
        ("tests/test_convert.py::test_inches_to_cm", "tests/test_convert.py::test_cm_to_inches"),
        ("tests/test_convert.py::test_zero",),
    ),
    Task(
        "newfunc",
        'Please add slugify(text) to textutil: lower case, words joined by "-" (slugify("Hello World") == "hello-world").',
        {
            "textutil.py": "def words(text):\n    return text.split()\n",
            "tests/test_textutil.py": 'from textutil import words\n\n\ndef test_words():\n    assert words("a b") == ["a", "b"]\n',
        },
        {
            "textutil.py": 'def words(text):\n    return text.split()\n\n\ndef slugify(text):\n    return "-".join(w.lower() for w in words(text))\n'
        },
        {
            "tests/test_textutil.py": 'from textutil import words\n\n\ndef test_words():\n    assert words("a b") == ["a", "b"]\n\n\ndef test_slugify():\n    from textutil import slugify\n\n    assert slugify("Hello World") == "hello-world"\n'
        },
        ("tests/test_textutil.py::test_slugify",),
        ("tests/test_textutil.py::test_words",),
    ),
    Task(
        "hang",
        "find_index([1, 3, 5], 5) never returns: the search loops forever when the target is right of the middle.",
        {
            "search.py": "def find_index(items, target):\n    lo, hi = 0, len(items) - 1\n    while lo <= hi:\n        mid = (lo + hi) // 2\n        if items[mid] == target:\n            return mid\n        if items[mid] < target:\n            lo = mid\n        else:\n            hi = mid - 1\n    return -1\n",
            "tests/test_search.py": "from search import find_index\n\n\ndef test_first():\n    assert find_index([1, 3, 5], 1) == 0\n",
        },
        {
            "search.py": "def find_index(items, target):\n    lo, hi = 0, len(items) - 1\n    while lo <= hi:\n        mid = (lo + hi) // 2\n        if items[mid] == target:\n            return mid\n        if items[mid] < target:\n            lo = mid + 1\n        else:\n            hi = mid - 1\n    return -1\n"
        },
        {
            "tests/test_search.py": "from search import find_index\n\n\ndef test_first():\n    assert find_index([1, 3, 5], 1) == 0\n\n\ndef test_last():\n    assert find_index([1, 3, 5], 5) == 2\n"
        },
        ("tests/test_search.py::test_last",),
        ("tests/test_search.py::test_first",),
        wrong={
            "search.py": 'def find_index(items, target):\n    """Binary search."""\n    lo, hi = 0, len(items) - 1\n    while lo <= hi:\n        mid = (lo + hi) // 2\n        if items[mid] == target:\n            return mid\n        if items[mid] < target:\n            lo = mid\n        else:\n            hi = mid - 1\n    return -1\n'
        },
        eval_timeout_s=HANG_TIMEOUT_S,
    ),
    Task(
        "p2p",
        'parse_bool should accept "True", "TRUE" and "yes" as true; today only "true" is.',
        {
            "flags.py": 'def parse_bool(text):\n    return text == "true"\n',
            "tests/test_flags.py": 'from flags import parse_bool\n\n\ndef test_false():\n    assert parse_bool("false") is False\n\n\ndef test_empty():\n    assert parse_bool("") is False\n',
        },
        {"flags.py": 'def parse_bool(text):\n    return text.strip().lower() in ("true", "yes", "1")\n'},
        {
            "tests/test_flags.py": 'from flags import parse_bool\n\n\ndef test_false():\n    assert parse_bool("false") is False\n\n\ndef test_empty():\n    assert parse_bool("") is False\n\n\ndef test_variants():\n    assert parse_bool("True") and parse_bool("TRUE") and parse_bool("yes")\n'
        },
        ("tests/test_flags.py::test_variants",),
        ("tests/test_flags.py::test_false", "tests/test_flags.py::test_empty"),
        wrong={"flags.py": "def parse_bool(text):\n    return bool(text)\n"},
    ),
)


def _git(repo: Path, *args: str) -> str:
    proc = subprocess.run(
        ["git", "-c", "user.name=fixture", "-c", "user.email=fixture@example.invalid", "-c", "init.defaultBranch=main", *args],
        cwd=repo,
        capture_output=True,
        text=True,
        check=True,
    )
    return proc.stdout


def _write(repo: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        p = repo / name
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)


def _diff_of(repo: Path, files: dict[str, str]) -> str:
    """The diff that ``files`` make against the base commit, the tree put back afterwards."""
    _write(repo, files)
    _git(repo, "add", "-A")
    diff = _git(repo, "diff", "--cached", "HEAD")
    _git(repo, "reset", "-q", "--hard", "HEAD")
    return diff


@dataclass(frozen=True)
class Fixtures:
    """What :func:`make_fixtures` built: the tasks file and, by task name, a wrong patch."""

    tasks_file: Path
    wrong_patches: dict[str, str]


def make_fixtures(folder: Path, names: tuple[str, ...] | None = None) -> Fixtures:
    """Create the repositories under ``folder/repos`` and ``folder/tasks.jsonl`` (``repo_path``
    relative to it); ``names`` picks tasks (default all six)."""
    folder.mkdir(parents=True, exist_ok=True)
    records, wrong = [], {}
    for task in TASKS:
        if names is not None and task.name not in names:
            continue
        repo = folder / "repos" / task.name
        repo.mkdir(parents=True)
        _git(repo, "init", "-q")
        _write(repo, {".gitignore": GITIGNORE, **task.base})
        _git(repo, "add", "-A")
        _git(repo, "commit", "-q", "-m", "base")
        base_commit = _git(repo, "rev-parse", "HEAD").strip()
        record: dict[str, object] = {
            "instance_id": f"fixture__{task.name}-1",
            "repo": f"fixture/{task.name}",
            "base_commit": base_commit,
            "problem_statement": task.problem,
            "patch": _diff_of(repo, task.gold),
            "test_patch": _diff_of(repo, task.tests),
            "FAIL_TO_PASS": json.dumps(list(task.fail_to_pass)),
            "PASS_TO_PASS": json.dumps(list(task.pass_to_pass)),
            "repo_path": f"repos/{task.name}",
            "test_cmd": TEST_CMD,
            "version": "0.1",
        }
        if task.eval_timeout_s is not None:
            record["eval_timeout_s"] = task.eval_timeout_s
        if task.wrong is not None:
            wrong[task.name] = _diff_of(repo, task.wrong)
        records.append(record)
    tasks_file = folder / "tasks.jsonl"
    tasks_file.write_text("".join(json.dumps(r) + "\n" for r in records))
    return Fixtures(tasks_file, wrong)


def main(argv: list[str] | None = None) -> int:
    """``python -m workers.envs.swe.examples DIR [NAME ...]``: write the example tasks into an
    empty or new ``DIR`` and print the instances file's path."""
    import sys  # the command line only

    args = list(sys.argv[1:] if argv is None else argv)
    if not args:
        print("usage: python -m workers.envs.swe.examples DIR [NAME ...]", file=sys.stderr)
        return 2
    folder, names = Path(args[0]), tuple(args[1:]) or None
    known = {t.name for t in TASKS}
    if names is not None and set(names) - known:
        print(
            f"error: unknown example task(s) {', '.join(sorted(set(names) - known))}; known: {', '.join(sorted(known))}",
            file=sys.stderr,
        )
        return 2
    if folder.exists() and any(folder.iterdir()):
        print(f"error: {folder} is not empty; the examples are written into an empty or new folder", file=sys.stderr)
        return 2
    folder.mkdir(parents=True, exist_ok=True)
    print(make_fixtures(folder, names).tasks_file)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
