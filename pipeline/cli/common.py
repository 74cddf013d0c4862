"""The parts every ``recap`` command shares: its two parser classes, their exceptions and number types.

Two parser kinds, because two error formats are part of the interface:

* :class:`OneLineParser` - ``recap``, ``run``, ``resume``, ``status``, ``estimate``, ``show``,
  ``env``: a usage error is the line ``recap: error: CMD: MESSAGE (see recap CMD --help)`` and
  the process exits with status 2 (``SystemExit``), like argparse itself.
* :class:`CommandParser` - ``sql``, ``report``, ``view``, ``data``: parsing raises
  :class:`UsageError` (or :class:`HelpExit` after ``--help``) so the command's ``main`` can
  print its own line and return a status; help goes to the stream the main was given.
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any, NoReturn, TextIO

from pipeline.errors import PreflightError, SpecError, one_line

if TYPE_CHECKING:
    from _typeshed import SupportsWrite

#: exit status of a usage error or a refusal
EXIT_USAGE = 2

# report, sql and view print the parts they skipped themselves ("warning: ..."); without a handler
# of the application's, Python's last-resort handler would print each a second time
logging.getLogger("reports").addHandler(logging.NullHandler())


class OneLineParser(argparse.ArgumentParser):
    """argparse whose usage errors are one line like every other error (``recap: error: ...``),
    exit status 2, instead of a usage block followed by the message. Help keeps the layout of
    its description and epilog (examples, exit statuses) and goes to stdout."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", argparse.RawDescriptionHelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        """Exit 2 with the one line ``recap: error: CMD: MESSAGE (see recap CMD --help)``."""
        where = self.prog.removeprefix("recap").strip()
        hint = f"recap {where} --help" if where else "recap --help"
        self.exit(EXIT_USAGE, one_line(f"recap: error: {where + ': ' if where else ''}{message} (see {hint})") + "\n")


class UsageError(Exception):
    """Bad command line of a :class:`CommandParser` command: one line on stderr, exit 2."""


def error_line(command: str, message: object) -> str:
    """The one format of every ``recap`` error: ``recap: error: COMMAND: MESSAGE`` on one line
    (``message`` a :class:`UsageError` too: its ``recap CMD:`` prefix, if any, is not repeated)."""
    text = str(message)
    for prefix in (f"recap {command}: ", f"{command}: "):
        text = text.removeprefix(prefix)
    return one_line(f"recap: error: {command}: {text}")


class HelpExit(Exception):
    """``--help`` (or argparse's own exit) was given: the help is printed, the main returns ``status``."""

    def __init__(self, status: int) -> None:
        super().__init__(status)
        self.status = status


class CommandParser(argparse.ArgumentParser):
    """argparse that raises instead of exiting, so a command's main can return a status; ``--help``
    prints to ``out`` (stdout by default). A usage error is :class:`UsageError` with the text
    ``PROG: MESSAGE``, or with ``hint``: ``MESSAGE (see PROG --help)``."""

    def __init__(self, *args: Any, out: TextIO | None = None, hint: bool = False, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", argparse.RawDescriptionHelpFormatter)
        super().__init__(*args, **kwargs)
        self.out = out
        self.hint = hint

    def error(self, message: str) -> NoReturn:
        """Raise :class:`UsageError` (the main prints it as one line)."""
        if self.hint:
            raise UsageError(f"{message} (see {self.prog} --help)")
        raise UsageError(f"{self.prog}: {message}")

    def exit(self, status: int = 0, message: str | None = None) -> NoReturn:
        """Write ``message`` (if any) to ``out`` and raise :class:`HelpExit`."""
        if message:
            (self.out or sys.stdout).write(message)
        raise HelpExit(status)

    def print_help(self, file: SupportsWrite[str] | None = None) -> None:
        """The help, to ``file`` or ``out`` or stdout."""
        (file or self.out or sys.stdout).write(self.format_help())

    def print_usage(self, file: SupportsWrite[str] | None = None) -> None:
        """The usage line, to ``file`` or ``out`` or stdout."""
        (file or self.out or sys.stdout).write(self.format_usage())


def finite_positive(text: str, what: str = "number") -> float:
    """argparse type: a finite number > 0 (``nan``, ``inf`` and ``-1`` are usage errors); ``what``
    names it in the message. The one rule for every such flag (``recap run --stop-grace`` too)."""
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid {what}: {text!r}") from None
    if not math.isfinite(x) or x <= 0:
        raise argparse.ArgumentTypeError(f"must be a finite {what} > 0, got {text!r}")
    return x


def seconds(text: str) -> float:
    """argparse type: a finite number of seconds > 0."""
    return finite_positive(text, "number of seconds")


@contextmanager
def named_source(source: str) -> Iterator[None]:
    """Prefix spec and preflight errors with the sweep file they come from (``run``, ``resume``, ``estimate``)."""
    try:
        yield
    except (SpecError, PreflightError) as exc:
        msg = str(exc)
        if msg.startswith(source + ":"):
            raise
        raise type(exc)(f"{source}: {msg}") from None


#: the object-store locations checked during this command (:func:`pipeline.cli.locations.check_location`);
#: ``main`` empties it, so a command run again in the same process checks them again
CHECKED_LOCATIONS: set[str] = set()
