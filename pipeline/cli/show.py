"""``recap show RUN_DIR EPISODE``: the command line of one episode's context tree (drawn by :mod:`pipeline.show`)."""

from __future__ import annotations

import argparse

from pipeline.cli.common import OneLineParser
from pipeline.cli.console import console
from pipeline.cli.locations import check_location
from pipeline.show import show_main

_EPILOG = """\
examples:
  recap show runs/demo 3f9c0a1b2d4e5f60       an episode id or a unit id (its latest attempt)
  recap show runs/demo 3f9c                   an unambiguous prefix of either

Find ids with: recap sql runs/demo "select episode_id, unit_id, arm, success from terminal"
exit status: 0 shown; 2 unknown or ambiguous EPISODE, or not a run folder
"""


def add_parser(sub: argparse._SubParsersAction[OneLineParser], name: str, help: str) -> None:  # noqa: A002
    """Add ``recap show`` to the ``recap`` parser."""
    sh = sub.add_parser(
        name,
        help=help,
        epilog=_EPILOG,
        description="One episode's ReCAP context tree (or a flat method's actions), then its tool calls, in the terminal.",
    )
    sh.add_argument("run_dir", help="the run folder (a path or an s3:// URI)")
    sh.add_argument("episode", help="an episode id, a unit id (its latest attempt), or an unambiguous prefix")


def execute(args: argparse.Namespace, command: str) -> int:
    """Print the episode's tree and tool calls; exit status 0."""
    check_location(args.run_dir)
    return show_main(args.run_dir, args.episode, console())
