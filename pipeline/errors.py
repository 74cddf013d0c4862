"""The pipeline's user-facing errors: each carries a one-line message the CLI prints as is.

Everything a researcher can get wrong in a sweep file or on the command line is raised as a
:class:`PipelineError` subclass *before* any model call or any write, so a bad input costs
nothing and leaves nothing behind.
"""

from __future__ import annotations


def one_line(message: object) -> str:
    """``message`` as one printable line: runs of whitespace (newlines included) become one
    space and every other control or format character (an escape code, a bidi override) its
    ``\\x..``/``\\u....`` escape, so a user string inside a message cannot move the cursor,
    recolour the terminal or split the line."""
    text = " ".join(str(message).split())
    if text.isprintable():
        return text
    out = []
    for ch in text:
        if ch.isprintable() or ch == " ":
            out.append(ch)
        else:
            code = ord(ch)
            out.append(f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}" if code < 0x10000 else f"\\U{code:08x}")
    return "".join(out)


class PipelineError(Exception):
    """Base class: ``str(err)`` is a complete one-line message (see :func:`one_line`)."""

    def __init__(self, message: str) -> None:
        super().__init__(one_line(message))


class SpecError(PipelineError):
    """The sweep file is malformed or names something that does not exist."""


class RunFolderError(PipelineError):
    """The output folder holds a different run, or is not a run folder at all."""


class PreflightError(PipelineError):
    """Something the run needs is missing (API key, prices for a capped model, the gateway)."""
