"""The pipeline's user-facing errors: each carries a one-line message the CLI prints as is.

Everything a researcher can get wrong in a sweep file or on the command line is raised as a
:class:`PipelineError` subclass *before* any model call or any write, so a bad input costs
nothing and leaves nothing behind.
"""

from __future__ import annotations


class PipelineError(Exception):
    """Base class: ``str(err)`` is a complete one-line message."""

    def __init__(self, message: str) -> None:
        super().__init__(" ".join(str(message).split()))


class SpecError(PipelineError):
    """The sweep file is malformed or names something that does not exist."""


class RunFolderError(PipelineError):
    """The output folder holds a different run, or is not a run folder at all."""


class PreflightError(PipelineError):
    """Something the run needs is missing (API key, prices for a capped model, the gateway)."""
