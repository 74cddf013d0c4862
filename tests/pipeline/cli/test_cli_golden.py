"""Every ``recap`` command's ``--help`` and usage-error output, byte for byte, against goldens.

The goldens in ``cli_golden/`` were written by ``python -m pipeline.cli ARGS`` processes (COLUMNS=100)
on the commit before the command line became the ``pipeline.cli`` package (issue 26): moving code
between modules must not change a byte of what a user sees. Each file holds the arguments, the
exit status, stdout and stderr of one call. A deliberate change of a help text rewrites its
golden: ``python -m tests.pipeline.cli.test_cli_golden --write`` (then review the diff).
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

from pipeline.cli import COMMANDS, command_parsers, main

GOLDEN = Path(__file__).resolve().with_name("cli_golden")
#: the actions of ``recap data`` (its parser is built apart: command_parsers leaves it out)
DATA_PATHS = [("data",), ("data", "list"), ("data", "check"), ("data", "fetch"), ("data", "images")]


def _cases() -> dict[str, list[str]]:
    """golden file name -> the arguments it records (its first line)."""
    return {p.name: ast.literal_eval(p.read_text().splitlines()[0].removeprefix("argv: ")) for p in sorted(GOLDEN.glob("*.txt"))}


def _record(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """What ``recap argv`` prints and returns, in the goldens' format."""
    try:
        code = main(list(argv))
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    out, err = capsys.readouterr()
    return f"argv: {argv}\nrc: {code}\n--- stdout\n{out}--- stderr\n{err}"


@pytest.fixture(autouse=True)
def _fixed_width(monkeypatch: pytest.MonkeyPatch) -> None:
    """argparse wraps help at $COLUMNS: the goldens were written at 100."""
    monkeypatch.setenv("COLUMNS", "100")
    monkeypatch.delenv("RECAP_LOG_LEVEL", raising=False)


@pytest.mark.parametrize("name", sorted(_cases()))
def test_output_is_the_golden_byte_for_byte(name: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert _record(_cases()[name], capsys) == (GOLDEN / name).read_text()


def test_the_goldens_cover_every_command_and_action() -> None:
    """A --help and a usage error for ``recap`` itself and every command path (a new command needs its goldens)."""
    paths = sorted(command_parsers()) + DATA_PATHS
    names = set(_cases())
    for path in paths:
        stem = "_".join(("recap", *path))
        assert {f"{stem}.help.txt", f"{stem}.bogus.txt"} <= names, stem
    assert {p[0] for p in paths if p} == set(COMMANDS)


def test_the_command_list() -> None:
    """The commands ``recap --help`` lists, in its order."""
    assert COMMANDS == ("run", "resume", "status", "estimate", "show", "sql", "report", "view", "env", "data")
    text = (GOLDEN / "recap.help.txt").read_text().split("commands:\n")[1]
    listed = [line.split()[0] for line in text.splitlines() if line.startswith("    ") and line[4] != " "]
    assert listed == list(COMMANDS)


@pytest.mark.parametrize("name", sorted(n for n in _cases() if not n.endswith(".help.txt")))
def test_every_usage_error_exits_2_with_one_line(name: str, capsys: pytest.CaptureFixture[str]) -> None:
    """An unknown option (``--bogus-flag``) or a missing argument for every command and action: status 2,
    nothing on stdout, one line on stderr."""
    argv = _cases()[name]
    try:
        code = main(list(argv))
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    assert (code, out) == (2, "")
    assert len(err.splitlines()) == 1 and err.endswith("\n"), err


if __name__ == "__main__" and sys.argv[1:] == ["--write"]:
    import os
    import subprocess

    env = dict(os.environ, COLUMNS="100", PYTHONPATH=str(GOLDEN.parents[3]))
    env.pop("RECAP_LOG_LEVEL", None)
    for golden, args in _cases().items():
        r = subprocess.run([sys.executable, "-m", "pipeline.cli", *args], env=env, capture_output=True, text=True, timeout=120)
        (GOLDEN / golden).write_text(f"argv: {args}\nrc: {r.returncode}\n--- stdout\n{r.stdout}--- stderr\n{r.stderr}")
