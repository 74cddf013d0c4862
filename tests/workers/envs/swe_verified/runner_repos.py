"""Two tiny repositories shaped like SWE-bench Verified's Django and SymPy instances, with records.

Django and SymPy are about 60 % of the 500 instances, and neither runs pytest: the harness runs
Django's ``./tests/runtests.py --verbosity 2 --settings=test_sqlite --parallel 1 <labels>`` with
module labels made from the test patch's files (``tests/text_utils/tests.py`` -> ``text_utils.tests``),
and SymPy's ``bin/test -C --verbose <files>``; its parsers (``swebench/harness/log_parsers/python.py``
``parse_log_django``, ``parse_log_sympy``) read their runners' own lines. So each repository here
has a runner written like the real one - the same arguments, the same output format - and a
record filed under the real repository name and a version the installed harness knows (its specs
give the eval script: conda activation, ``pip install -e .``, which fails harmlessly here, the
test patch, the test command):

* ``django/django`` 4.0: ``tests/runtests.py`` takes module labels (argparse: pytest's ``-rA`` is
  refused, as Django's refuses it), imports them from ``tests/``, runs them with unittest at
  verbosity 2 and prints Django's runner lines to stderr (``test_x (mod.tests.Class) ... ok``, the
  ``FAIL:`` blocks, ``Ran N tests``). Ids are Django's: ``test_word (text_utils.tests.CapfirstTests)``.
* ``sympy/sympy`` 1.12: ``bin/test`` takes test files, runs their ``test_*`` functions in file
  order and prints SymPy's verbose report (``sympy/testing/runtests.py`` ``PyTestReporter``): the
  header, ``<file>[n]``, one ``test_x ok``/``test_x F`` line each, the file's ``[OK]``/``[FAIL]``
  right-aligned at column 80 on the last test's line (so, as with real SymPy logs, the harness's
  parser cannot read the last test of a file: SWE-bench's lists never name it, nor do ours), the
  failures' ``____ file:test ____`` blocks and ``tests finished: ...``. Ids are SymPy's: ``test_zero``.
"""

from __future__ import annotations

import json
import secrets
import subprocess
from dataclasses import dataclass
from pathlib import Path

DJANGO_RUNTESTS = '''#!/usr/bin/env python
"""Runs test modules named as Django's runtests.py names them (labels under tests/), with its output."""
import argparse
import os
import sys
import unittest


class Result(unittest.TextTestResult):
    def getDescription(self, test):
        return "%s (%s.%s)" % (test._testMethodName, type(test).__module__, type(test).__qualname__)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("modules", nargs="*", metavar="module")
    parser.add_argument("-v", "--verbosity", type=int, default=1, choices=[0, 1, 2, 3])
    parser.add_argument("--settings")
    parser.add_argument("--parallel", default="0")
    options = parser.parse_args()
    here = os.path.dirname(os.path.abspath(__file__))
    sys.path[:0] = [here, os.path.dirname(here)]
    print("Testing against Django installed in '%s' with up to %s processes" % (os.path.join(os.path.dirname(here), "djmini"), options.parallel), file=sys.stderr)
    suite = unittest.TestSuite()
    for label in options.modules:
        print("Importing application %s" % label.split(".")[0], file=sys.stderr)
        suite.addTests(unittest.defaultTestLoader.loadTestsFromName(label))
    print("Found %d test(s)." % suite.countTestCases(), file=sys.stderr)
    print("Skipping setup of unused database(s): default, other.", file=sys.stderr)
    print("System check identified no issues (0 silenced).", file=sys.stderr)
    result = unittest.TextTestRunner(verbosity=options.verbosity, resultclass=Result).run(suite)
    return 0 if result.wasSuccessful() else 1


if __name__ == "__main__":
    sys.exit(main())
'''

SYMPY_BIN_TEST = '''#!/usr/bin/env python
"""Runs test files as SymPy's bin/test does (their test_* functions in file order), with its verbose report."""
import argparse
import importlib.util
import os
import platform
import sys
import time
import traceback

WIDTH = 80


def center(text, delim):
    text = " %s " % text if text else text
    left = (WIDTH - len(text)) // 2
    return delim * left + text + delim * (WIDTH - left - len(text))


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("paths", nargs="*")
    parser.add_argument("-C", "--no-cache", action="store_true")
    parser.add_argument("-v", "--verbose", action="store_true")
    options = parser.parse_args()
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    sys.path.insert(0, root)
    out = sys.stdout
    out.write(center("test process starts", "=") + "\\n")
    out.write("executable:         %s  (%s-final-0) [CPython]\\n" % (sys.executable, platform.python_version()))
    out.write("architecture:       64-bit\\ncache:              no\\nground types:       python \\n")
    out.write("numpy:              None\\nrandom seed:        20250101\\nhash randomization: on (PYTHONHASHSEED=1)\\n\\n")
    started = time.time()
    passed, failed = 0, []
    for path in options.paths:
        spec = importlib.util.spec_from_file_location(path[:-3].replace("/", "."), os.path.join(root, path))
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        tests = sorted(
            (f for name, f in vars(module).items() if name.startswith("test_") and callable(f)),
            key=lambda f: f.__code__.co_firstlineno,
        )
        head = "%s[%d] " % (path, len(tests))
        out.write(head)
        pos, file_failed = len(head), False
        for f in tests:
            out.write("\\n" + f.__name__ + " ")
            pos = len(f.__name__) + 1
            try:
                f()
            except Exception:
                out.write("F")
                pos += 1
                failed.append((path, f.__name__, traceback.format_exc()))
                file_failed = True
            else:
                out.write("ok")
                pos += 2
                passed += 1
        out.write(" ")
        mark = "[FAIL]" if file_failed else "[OK]"
        out.write(" " * (WIDTH - pos - 1 - len(mark)) + mark + "\\n\\n")
    if failed:
        out.write("\\n")
        for path, name, text in failed:
            out.write(center("", "_") + "\\n" + center("%s:%s" % (path, name), "_") + "\\n" + text)
        out.write("\\n")
    counts = "%d passed, %d failed" % (passed, len(failed)) if failed else "%d passed" % passed
    out.write(center("tests finished: %s, in %.2f seconds" % (counts, time.time() - started), "=") + "\\n")
    if failed:
        out.write("DO *NOT* COMMIT!\\n")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
'''


@dataclass(frozen=True)
class Shape:
    """One repository's files: at the base commit, the gold fix, the test patch, a patch that leaves the bug."""

    repo: str
    version: str
    number: str
    base: dict[str, str]
    executables: tuple[str, ...]
    gold: dict[str, str]
    tests: dict[str, str]
    wrong: dict[str, str]
    fail_to_pass: tuple[str, ...]
    pass_to_pass: tuple[str, ...]
    problem: str


DJANGO_TESTS_BASE = """import unittest

from djmini.text import capfirst


class CapfirstTests(unittest.TestCase):
    def test_empty(self):
        self.assertEqual(capfirst(""), "")
"""

SYMPY_TESTS_BASE = """from symini.core import sign


def test_positive():
    assert sign(3) == 1


def test_negative():
    assert sign(-2) == -1


def test_type():
    assert isinstance(sign(1), int)
"""

DJANGO = Shape(
    repo="django/django",
    version="4.0",
    number="1",
    base={
        "djmini/__init__.py": "",
        "djmini/text.py": "def capfirst(value):\n    return value[:1].upper() + value[2:]\n",
        "tests/runtests.py": DJANGO_RUNTESTS,
        "tests/text_utils/__init__.py": "",
        "tests/text_utils/tests.py": DJANGO_TESTS_BASE,
    },
    executables=("tests/runtests.py",),
    gold={"djmini/text.py": "def capfirst(value):\n    return value[:1].upper() + value[1:]\n"},
    tests={
        "tests/text_utils/tests.py": DJANGO_TESTS_BASE
        + '\n    def test_word(self):\n        self.assertEqual(capfirst("hello"), "Hello")\n'
    },
    wrong={
        "djmini/text.py": "def capfirst(value):\n    # upper-case the first letter\n    return value[:1].upper() + value[2:]\n"
    },
    fail_to_pass=("test_word (text_utils.tests.CapfirstTests)",),
    pass_to_pass=("test_empty (text_utils.tests.CapfirstTests)",),
    problem="capfirst('hello') gives 'Hllo': the second letter is lost.",
)

SYMPY = Shape(
    repo="sympy/sympy",
    version="1.12",
    number="2",
    base={
        "symini/__init__.py": "",
        "symini/core.py": "def sign(x):\n    return 1 if x >= 0 else -1\n",
        "symini/tests/__init__.py": "",
        "symini/tests/test_core.py": SYMPY_TESTS_BASE,
        "bin/test": SYMPY_BIN_TEST,
    },
    executables=("bin/test",),
    gold={"symini/core.py": "def sign(x):\n    return 1 if x > 0 else -1 if x < 0 else 0\n"},
    tests={
        "symini/tests/test_core.py": SYMPY_TESTS_BASE.replace(
            "\n\ndef test_type():", "\n\ndef test_zero():\n    assert sign(0) == 0\n\n\ndef test_type():"
        )
    },
    wrong={"symini/core.py": "def sign(x):\n    # the sign of x\n    return 1 if x >= 0 else -1\n"},
    fail_to_pass=("test_zero",),
    pass_to_pass=("test_positive", "test_negative"),
    problem="sign(0) is 1; it should be 0.",
)

SHAPES = {"django": DJANGO, "sympy": SYMPY}


def _git(repo: Path, *args: str) -> str:
    return subprocess.run(
        ["git", "-c", "user.name=fixture", "-c", "user.email=fixture@example.invalid", "-c", "init.defaultBranch=main", *args],
        cwd=repo,
        capture_output=True,
        text=True,
        check=True,
    ).stdout


def _diff(repo: Path, files: dict[str, str]) -> str:
    for name, text in files.items():
        (repo / name).write_text(text)
    _git(repo, "add", "-A")
    diff = _git(repo, "diff", "--cached", "HEAD")
    _git(repo, "reset", "-q", "--hard", "HEAD")
    return diff


@dataclass(frozen=True)
class Built:
    """A built repository: its folder, its record (the dataset's 13 fields) and a patch that leaves the bug."""

    path: Path
    record: dict[str, str]
    wrong_patch: str


def build(shape: Shape, folder: Path) -> Built:
    """The repository of ``shape`` under ``folder`` at its base commit, with a record of a unique id."""
    repo = folder / shape.repo.replace("/", "__")
    repo.mkdir(parents=True)
    _git(repo, "init", "-q")
    for name, text in shape.base.items():
        (repo / name).parent.mkdir(parents=True, exist_ok=True)
        (repo / name).write_text(text)
    for name in shape.executables:
        (repo / name).chmod(0o755)
    _git(repo, "add", "-A")
    _git(repo, "commit", "-q", "-m", "base")
    base = _git(repo, "rev-parse", "HEAD").strip()
    owner, name = shape.repo.split("/")
    record = {
        "repo": shape.repo,
        "instance_id": f"{owner}__{name}-{secrets.randbelow(10**9) + 10**9}",
        "base_commit": base,
        "patch": _diff(repo, shape.gold),
        "test_patch": _diff(repo, shape.tests),
        "problem_statement": shape.problem,
        "hints_text": "",
        "created_at": "2024-01-01T00:00:00Z",
        "version": shape.version,
        "FAIL_TO_PASS": json.dumps(list(shape.fail_to_pass)),
        "PASS_TO_PASS": json.dumps(list(shape.pass_to_pass)),
        "environment_setup_commit": base,
        "difficulty": "<15 min fix",
    }
    return Built(repo, record, _diff(repo, shape.wrong))
