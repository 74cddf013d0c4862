"""Every ``recap`` command's ``--help``: status 0, on stdout, every option with a one-line
description, at least one example; options work before or after the positional arguments."""

from __future__ import annotations

import argparse
import io
from pathlib import Path
from typing import Any

import pytest

from pipeline.cli import COMMANDS, command_parsers, main
from tests.doubles.known_run import write_run_a, write_run_b

#: every command path whose --help this file checks (data is pipeline.cli.data's own parser)
PATHS = [
    (),
    ("run",),
    ("resume",),
    ("status",),
    ("estimate",),
    ("show",),
    ("sql",),
    ("report",),
    ("view",),
    ("env",),
    ("env", "list"),
    ("env", "play"),
    ("env", "replay"),
    ("env", "standin"),
]


def _call(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """(exit status, stdout, stderr) of ``recap argv``, whether main returns or exits."""
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    out, err = capsys.readouterr()
    return code, out, err


def test_every_command_has_a_parser_here():
    assert sorted(command_parsers()) == sorted(PATHS)
    assert set(COMMANDS) == {p[0] for p in PATHS if p} | {"data"}


@pytest.mark.parametrize("path", PATHS, ids=lambda p: " ".join(("recap", *p)))
def test_help_lists_every_option_with_a_description_and_an_example(path, capsys):
    parser = command_parsers()[path]
    code, out, err = _call([*path, "--help"], capsys)
    assert (code, err) == (0, "")
    assert "usage:" in out
    assert "example" in out.lower()
    for action in parser._actions:
        what = action.option_strings or [action.metavar or action.dest]
        assert action.help and action.help is not argparse.SUPPRESS and action.help.strip(), f"{what} has no help text"
        assert "\n" not in action.help, f"{what}: the help text is more than one line"
        if action.option_strings:
            for opt in action.option_strings:
                assert opt in out, f"{opt} is not in recap {' '.join(path)} --help"
        else:
            assert str(action.metavar or action.dest) in out
        if isinstance(action, argparse._SubParsersAction):
            for name in action.choices:
                assert f"    {name} " in out, f"{name} is not listed by recap {' '.join(path)} --help"
            for choice in action._choices_actions:
                assert choice.help and "\n" not in choice.help, f"{choice.dest} has no one-line help"


def test_top_level_help_lists_every_command(capsys):
    code, out, _ = _call(["--help"], capsys)
    assert code == 0
    for name in COMMANDS:
        assert f"\n    {name} " in out, name


def test_help_anywhere_after_the_command(capsys):
    """``--help`` after positionals prints the same help (sql and report included)."""
    for argv, first in (
        (["sql", "runs/x", "--help"], ["sql", "--help"]),
        (["report", "runs/x", "--format", "md", "--help"], ["report", "--help"]),
        (["run", "sweep.yaml", "--help"], ["run", "--help"]),
    ):
        assert _call(argv, capsys)[:2] == _call(first, capsys)[:2]


def test_run_and_resume_help_give_the_exit_statuses(capsys):
    for cmd in ("run", "resume"):
        out = " ".join(_call([cmd, "--help"], capsys)[1].split())  # words, whatever the wrapping
        for line in (
            "0    all units done",
            "2    bad input",
            "folder in use",
            "sink lost",
            "3    a cap stopped it",
            "4    a unit ended in an infrastructure failure",
            "130  interrupted",
            "recap resume RUN --repair",
        ):
            assert " ".join(line.split()) in out, (cmd, line)
        assert "recap resume RUN" in out


@pytest.mark.parametrize("action", [[], ["list"], ["check"], ["fetch"]], ids=lambda a: " ".join(["recap data", *a]))
def test_data_help_works(action, capsys):
    code, out, err = _call(["data", *action, "--help"], capsys)
    assert (code, err) == (0, "")
    assert out.startswith("usage: recap data")
    assert "--help" in out


def test_no_arguments_is_one_usage_line_and_a_hint(capsys):
    code, out, err = _call([], capsys)
    assert (code, out) == (2, "")
    assert len(err.splitlines()) == 1
    assert err.startswith("usage: recap ") and "recap --help" in err
    for name in COMMANDS:
        assert name in err


@pytest.mark.parametrize(
    "argv, start",
    [
        (["nosuch"], "recap: error: argument COMMAND: invalid choice: 'nosuch'"),
        (["run"], "recap: error: run: the following arguments are required: spec"),
        (["run", "x.yaml", "--progress", "loud"], "recap: error: run: argument --progress: invalid choice"),
        (["resume", "runs/x", "--workers", "many"], "recap: error: resume: argument --workers: invalid int value"),
        (["env"], "recap: error: env: the following arguments are required: ACTION"),
        (["env", "play", "blocksworld/3@1", "--step-multiplier", "nan"], "recap: error: env play: argument --step-multiplier"),
        (["show", "runs/x"], "recap: error: show: the following arguments are required: episode"),
        (["sql", "--max-rows"], "recap: error: sql: argument --max-rows: expected one argument"),
        (["sql", "--csv", "--json", "runs/x", "SELECT 1"], "recap: error: sql: argument --json: not allowed with argument --csv"),
        (["report", "--format"], "recap: error: report: argument --format: expected one argument"),
        (["report"], "recap: error: report: the following arguments are required: RUN_DIR"),
    ],
)
def test_usage_errors_stay_one_line_exit_2(argv, start, capsys):
    code, out, err = _call(argv, capsys)
    assert (code, out) == (2, "")
    assert len(err.splitlines()) == 1 and err.startswith(start), err


# -- options before, between or after the positional arguments -------------------------------


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    base = tmp_path_factory.mktemp("help_runs")
    return write_run_a(base / "runA"), write_run_b(base / "runB")


QUERY = "SELECT run_id, count(*) AS n, sum(cost_usd) AS usd FROM terminal GROUP BY run_id ORDER BY run_id"


@pytest.fixture
def query_runs(monkeypatch: pytest.MonkeyPatch) -> dict[str, tuple[str, str, Any]]:
    """``recap sql``'s query process run once per distinct (job, limits): an argv that settles to a job
    already run gets that run's exact output and status replayed (the query process is a function of
    them; each costs a Python start with DuckDB and pyarrow). Returns the runs by job, filled as the
    test goes: a test sees how many distinct jobs its argument orders settled to."""
    import json

    import pipeline.cli.sql as sql_cli

    real = sql_cli.run_limited
    done: dict[str, tuple[str, str, Any]] = {}

    def once(job, limits, out, err):
        key = json.dumps([job, limits.memory_bytes, limits.timeout_s, limits.memory_text], sort_keys=True)
        if key not in done:
            o, e = io.StringIO(), io.StringIO()
            outcome = real(job, limits, o, e)
            done[key] = (o.getvalue(), e.getvalue(), outcome)
        text, errors, outcome = done[key]
        out.write(text)
        err.write(errors)
        return outcome

    monkeypatch.setattr(sql_cli, "run_limited", once)
    return done


@pytest.mark.parametrize("opts", [["--csv"], ["--json"], ["--max-rows", "1"]], ids=lambda o: " ".join(o))
def test_sql_options_in_any_position(runs, opts, capsys, query_runs):
    a, b = map(str, runs)
    orders = [
        ["sql", a, *opts, QUERY],
        ["sql", *opts, a, QUERY],
        ["sql", a, QUERY, *opts],
        ["sql", a, *opts, b, QUERY],
        ["sql", *opts, a, b, QUERY],
        ["sql", a, b, QUERY, *opts],
    ]
    results = [_call(argv, capsys) for argv in orders]
    assert results[0][0] == 0 and results[0][2] == "", results[0]
    assert results[3][0] == 0 and results[3][1] != results[0][1]  # two runs: more rows
    assert results[:3] == [results[0]] * 3
    assert results[3:] == [results[3]] * 3
    assert len(query_runs) == 2  # every order settled to the same job as its first (one run, two runs)


def test_sql_file_and_named_query_in_any_position(runs, tmp_path, capsys, query_runs):
    a = str(runs[0])
    q = tmp_path / "q.sql"
    q.write_text(QUERY + "\n")
    by_file = [
        _call(argv, capsys)
        for argv in (
            ["sql", "--file", str(q), a, "--csv"],
            ["sql", a, "--file", str(q), "--csv"],
            ["sql", "--csv", a, "--file", str(q)],
        )
    ]
    assert by_file[0][0] == 0 and by_file == [by_file[0]] * 3
    assert by_file[0] == _call(["sql", a, QUERY, "--csv"], capsys)
    named = [
        _call(argv, capsys)
        for argv in (["sql", a, "@overview", "--json"], ["sql", "--json", a, "@overview"], ["sql", a, "--json", "@overview"])
    ]
    assert named[0][0] == 0 and '"units"' in named[0][1] and named == [named[0]] * 3
    assert len(query_runs) == 3  # one job per query text (the file keeps its newline), whatever the order


@pytest.fixture
def report_builds(monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    """``recap report`` builds its report once per distinct (run folders, options): an argv that settles
    to a build already made writes that report again (the build is a function of them; the files are
    still written by each call). Returns the builds by their arguments, filled as the test goes."""
    import pipeline.cli.report as report_cli

    real = report_cli.build_report
    done: dict[str, Any] = {}

    def once(run_dirs, options):
        key = repr(([str(Path(d).resolve()) for d in run_dirs], options))
        if key not in done:
            done[key] = real(run_dirs, options)
        return done[key]

    monkeypatch.setattr(report_cli, "build_report", once)
    return done


def test_report_options_in_any_position(runs, tmp_path, capsys, report_builds):
    a, b = map(str, runs)
    out = str(tmp_path / "rep")
    orders = [
        ["report", a, "--format", "md", "--out", out, "--title", "T"],
        ["report", "--format", "md", "--out", out, "--title", "T", a],
        ["report", "--out", out, a, "--format", "md", "--title", "T"],
    ]
    texts = []
    for argv in orders:
        code, stdout, err = _call(argv, capsys)
        assert code == 0, err
        texts.append((stdout, (tmp_path / "rep" / "report.md").read_text()))
        (tmp_path / "rep" / "report.md").unlink()
    assert texts == [texts[0]] * 3
    assert texts[0][0].startswith("wrote ") and texts[0][0].splitlines()[0].endswith(f" files to {out} (md)")
    # several run folders with options between them
    both = [
        ["report", a, "--out", out, b, "--format", "md"],
        ["report", "--format", "md", a, b, "--out", out],
        ["report", a, b, "--format", "md", "--out", out],
    ]
    md = []
    for argv in both:
        code, _, err = _call(argv, capsys)
        assert code == 0, err
        md.append((tmp_path / "rep" / "report.md").read_text())
    assert md == [md[0]] * 3 and md[0] != texts[0][1]
    assert len(report_builds) == 2  # every order settled to the build of its first (one run, two runs)
