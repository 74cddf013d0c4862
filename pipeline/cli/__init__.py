"""The ``recap`` command: reads the command word and hands the rest to that command's module.

Every user error is one line on stderr (``recap: error: ...``) and exit status 2, raised before
any model call and before anything is written. Exit status of ``run``/``resume``: 0 when every
unit is done, 3 when work remains (a cap stopped it), 4 when a unit ended in an infrastructure
failure, 130 when interrupted. Every command's ``--help`` (stdout, status 0) lists its options
and examples; ``recap`` alone prints its usage line and a hint on stderr, status 2.

One module per command (group) in this package: :mod:`~pipeline.cli.run` (run, resume),
:mod:`~pipeline.cli.status`, :mod:`~pipeline.cli.estimate`, :mod:`~pipeline.cli.show`,
:mod:`~pipeline.cli.sql`, :mod:`~pipeline.cli.report`, :mod:`~pipeline.cli.view`,
:mod:`~pipeline.cli.env`, :mod:`~pipeline.cli.data`; the parser classes and exceptions they share
are :mod:`~pipeline.cli.common`. A command's module is imported only when that command runs
(:data:`_TABLE`), so ``recap --help`` stays fast and ``recap sql`` never imports Ray or litellm.
Inside ``run``, the driver (Ray) and the gateway backend are imported once a sweep is accepted,
and litellm is asked only what its files cannot answer (:mod:`pipeline.litellm_files`): a refused
sweep file costs about a second of CPU, not the seven of importing litellm.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Collection, Sequence
from typing import Protocol, cast

os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")

from pipeline.cli.common import CHECKED_LOCATIONS, EXIT_USAGE, OneLineParser  # noqa: E402
from pipeline.errors import PipelineError  # noqa: E402
from workers.log_setup import DEFAULT_LEVEL as DEFAULT_LOG_LEVEL  # noqa: E402
from workers.log_setup import LEVEL_VAR as LOG_LEVEL_VAR  # noqa: E402
from workers.log_setup import LEVELS as LOG_LEVELS  # noqa: E402
from workers.log_setup import configure as configure_logging  # noqa: E402

#: command -> (the module that runs it, its line in ``recap --help``), in the order ``recap --help`` lists them
_TABLE: dict[str, tuple[str, str]] = {
    "run": ("pipeline.cli.run", "run a sweep file"),
    "resume": ("pipeline.cli.run", "finish a run after a crash or with a higher cap"),
    "status": ("pipeline.cli.status", "units done/total, success, spend of a run folder"),
    "estimate": ("pipeline.cli.estimate", "units, calls, tokens and a cost range of a sweep file"),
    "show": ("pipeline.cli.show", "one episode's ReCAP context tree"),
    "sql": ("pipeline.cli.sql", "read-only SQL over the tables of one or more run folders (--csv, --json, --file, @NAME)"),
    "report": ("pipeline.cli.report", "build the report (Markdown, HTML, LaTeX, CSV) of one or more runs"),
    "view": ("pipeline.cli.view", "browse every episode of one or more runs in a local web viewer (read-only)"),
    "env": ("pipeline.cli.env", "list, play or replay benchmark instances (no model)"),
    "data": ("pipeline.cli.data", "list, check or fetch the benchmark data folders (recap data --help)"),
}

#: the commands in the order ``recap --help`` lists them
COMMANDS = tuple(_TABLE)

#: commands that read all their own arguments (their own parsers and error lines): ``main(argv)``
_HANDED_OFF = ("sql", "report", "view", "data")

_MAIN_EPILOG = """\
examples:
  recap estimate examples/demo.yaml         units, calls, tokens and a cost range; spends nothing
  recap run examples/demo.yaml              run the sweep (local Ray); prints the run folder
  recap status runs/demo                    done/total, success, spend (also mid-run)
  recap resume runs/demo --run-cap 60       finish after a crash or with a higher cap
  recap sql runs/demo @failure_modes        read-only SQL over the run's tables
  recap report runs/demo                    Markdown/HTML/LaTeX/CSV report under runs/demo/report
  recap view runs/demo                      browse every episode on http://127.0.0.1:8765/

Each command's options and examples: recap COMMAND --help. Every error is one line on stderr.
"""


class _Parsed(Protocol):
    """A command module whose arguments the ``recap`` parser reads (run, resume, status, estimate, show, env)."""

    def add_parser(self, sub: argparse._SubParsersAction[OneLineParser], name: str, help: str) -> None: ...  # noqa: A002, D102

    def execute(self, args: argparse.Namespace, command: str) -> int: ...  # noqa: D102


class _HandedOff(Protocol):
    """A command module that reads its own arguments (sql, report, view, data)."""

    def main(self, argv: list[str]) -> int: ...  # noqa: D102

    def parser(self) -> argparse.ArgumentParser: ...  # noqa: D102


def _module(name: str) -> object:
    """The module of command ``name``, imported now (a command's own heavy imports wait for its work)."""
    return importlib.import_module(_TABLE[name][0])


def _parser(real: Collection[str] = ()) -> argparse.ArgumentParser:
    """The ``recap`` parser; the commands in ``real`` get their full parser (their module is
    imported), the others only their line in ``recap --help``."""
    p = OneLineParser(prog="recap", description="Run and inspect ReCAP evaluation sweeps.", epilog=_MAIN_EPILOG)
    p.add_argument(
        "--log-level",
        choices=LOG_LEVELS,
        default=DEFAULT_LOG_LEVEL,
        help="diagnostic lines on stderr (and in the Ray workers' logs) from this level up; "
        "accepted before or after any command (default: warning, or $RECAP_LOG_LEVEL)",
    )
    sub = p.add_subparsers(
        dest="cmd",
        required=True,
        metavar="COMMAND",
        title="commands",
        help="one of the commands below; recap COMMAND --help for its options and examples",
    )
    for name, (_, line) in _TABLE.items():
        if name in real and name not in _HANDED_OFF:
            cast(_Parsed, _module(name)).add_parser(sub, name, line)
        else:
            sub.add_parser(name, help=line, add_help=False)
    return p


def command_parsers() -> dict[tuple[str, ...], argparse.ArgumentParser]:
    """The parser that reads each command's arguments (and prints its ``--help``), by command
    path: ``()`` is ``recap`` itself, ``("env", "list")`` is ``recap env list``. ``data`` is left
    out (:mod:`pipeline.cli.data` builds its parser with the benchmarks' folder names)."""
    found: dict[tuple[str, ...], argparse.ArgumentParser] = {}

    def walk(path: tuple[str, ...], parser: argparse.ArgumentParser) -> None:
        found[path] = parser
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, child in action.choices.items():
                    walk((*path, name), child)

    walk((), _parser(real=COMMANDS))
    del found[("data",)]
    for name in ("sql", "report", "view"):
        found[(name,)] = cast(_HandedOff, _module(name)).parser()
    return found


def _command_word(argv: Sequence[str]) -> str | None:
    """The word argparse takes as the command: the first argument that is not an option (the only
    option of ``recap`` itself that takes a value, ``--log-level``, is gone by then)."""
    return next((a for a in argv if not a.startswith("-")), None)


def _take_log_level(argv: list[str]) -> str | None:
    """Remove ``--log-level LEVEL`` (or ``--log-level=LEVEL``) from ``argv`` wherever it stands
    (before or after the command: every command accepts it) and return the level."""
    level = None
    for i, arg in enumerate(argv):
        if arg == "--":
            break
        if arg == "--log-level" or arg.startswith("--log-level="):
            if "=" in arg:
                level, drop = arg.split("=", 1)[1], 1
            elif i + 1 < len(argv):
                level, drop = argv[i + 1], 2
            else:
                raise PipelineError(f"--log-level needs a level: {', '.join(LOG_LEVELS)}")
            if level.lower() not in LOG_LEVELS:
                raise PipelineError(f"--log-level: unknown level {level!r}; one of {', '.join(LOG_LEVELS)}")
            del argv[i : i + drop]
            break
    return level


def _hand_off(name: str, argv: list[str]) -> int:
    """Run a command that reads its own arguments (``--help`` included: its parser says it all)."""
    if name == "data":  # data's errors are its own (exit 1 for a failed check), printed by it
        return cast(_HandedOff, _module(name)).main(argv)
    try:
        return cast(_HandedOff, _module(name)).main(argv)
    except PipelineError as exc:
        print(f"recap: error: {exc}", file=sys.stderr)
        return EXIT_USAGE


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``recap``: returns the exit status (see the module docstring) instead of raising, so user
    errors stay one line."""
    argv = list(sys.argv[1:] if argv is None else argv)
    CHECKED_LOCATIONS.clear()
    try:
        level = _take_log_level(argv)
    except PipelineError as exc:
        print(f"recap: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    configure_logging(level or os.environ.get(LOG_LEVEL_VAR, "").lower() or DEFAULT_LOG_LEVEL)
    if argv and argv[0] == "data":
        return _hand_off("data", argv[1:])
    if not argv:
        usage = _parser().format_usage().strip()
        print(f"{usage}  (COMMAND: {', '.join(COMMANDS)}; see recap --help)", file=sys.stderr)
        return EXIT_USAGE
    if argv[0] in _HANDED_OFF:
        return _hand_off(argv[0], argv[1:])
    word = _command_word(argv)
    args = _parser(real=() if word is None else (word,)).parse_args(argv)
    try:
        return cast(_Parsed, _module(args.cmd)).execute(args, "recap " + " ".join(argv))
    except PipelineError as exc:
        print(f"recap: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("recap: interrupted", file=sys.stderr)
        return 130
