"""``recap status RUN_DIR``: a run folder's summary table; a damaged folder is one error line, never a traceback."""

from __future__ import annotations

import argparse

from pipeline.cli.common import OneLineParser
from pipeline.cli.console import render_safely
from pipeline.cli.locations import check_location
from pipeline.errors import PipelineError
from pipeline.store import RunStore
from pipeline.summary import collect, render

_EPILOG = """\
examples:
  recap status runs/demo
  recap status s3://bucket/runs/demo

Works mid-run and after a crash; names unreadable part files and a torn ledger line.
exit status: 0 shown; 2 not a run folder (or unreadable)
"""


def add_parser(sub: argparse._SubParsersAction[OneLineParser], name: str, help: str) -> None:  # noqa: A002
    """Add ``recap status`` to the ``recap`` parser."""
    st = sub.add_parser(
        name, help=help, epilog=_EPILOG, description="Units done/total, success, spend and problems of a run folder."
    )
    st.add_argument("run_dir", help="the run folder (a path or an s3:// URI)")


def execute(args: argparse.Namespace, command: str) -> int:
    """Print the run's summary table; exit status 0."""
    check_location(args.run_dir)
    store = RunStore(args.run_dir)
    store.require_identity()
    try:
        report = collect(store)
    except PipelineError:
        raise
    except Exception as exc:  # status must never die with a traceback on a damaged folder
        raise PipelineError(
            f"cannot read {args.run_dir}: {type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
        ) from None
    render_safely(render, report)
    return 0
