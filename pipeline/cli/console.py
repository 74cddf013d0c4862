"""Terminal output of the ``recap`` commands: rich consoles, and user strings never read as markup."""

from __future__ import annotations

import io
import os
import sys
from collections.abc import Callable

from rich.console import Console
from rich.errors import MarkupError
from rich.text import Text


def plain(text: str) -> Text:
    """``text`` for a rich console with markup off: user strings (run and model names, paths,
    unit keys) are printed as they are, never read as ``[style]`` tags."""
    return Text(text)


def styled(text: str, style: str) -> Text:
    """``text`` in ``style``, its own characters never read as markup."""
    return Text(text, style=style)


def console(stderr: bool = False, *, markup: bool = True) -> Console:
    """A rich console: the terminal's width; ``$COLUMNS`` when set, else 200 when writing to a file
    or pipe, so tables keep one line per row (and fit a width the caller asks for)."""
    stream = sys.stderr if stderr else sys.stdout
    columns = os.environ.get("COLUMNS", "")
    if getattr(stream, "isatty", lambda: False)():
        width = None
    else:
        width = int(columns) if columns.isdigit() and int(columns) > 0 else 200
    return Console(file=stream, highlight=False, width=width, markup=markup)


def render_safely(render: Callable[..., object], *args: object) -> None:
    """``render(*args, console)`` where the rendered text holds user strings (run, method and
    model names, paths) that may read as Rich markup (``[/]`` in an old run's label would raise
    on every ``recap status``): rendered once off screen, and with markup off if that fails."""
    out = console()
    try:
        render(*args, Console(file=io.StringIO(), highlight=False, width=out.width))
    except MarkupError:
        out = console(markup=False)
    render(*args, out)
