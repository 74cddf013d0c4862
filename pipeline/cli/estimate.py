"""``recap estimate SPEC``: the plan and its expected cost, without connecting to Ray or calling any model."""

from __future__ import annotations

import argparse
from pathlib import Path

from pipeline.cli.common import OneLineParser, named_source
from pipeline.cli.console import render_safely
from pipeline.estimate import estimate, render
from pipeline.preflight import check_models, check_plan
from pipeline.spec import load_spec
from pipeline.units import expand

_EPILOG = """\
examples:
  recap estimate examples/real-model.yaml
  recap estimate examples/demo.yaml

Reads the sweep file only: no model is called, nothing is written.
exit status: 0 shown; 2 bad sweep file
"""


def add_parser(sub: argparse._SubParsersAction[OneLineParser], name: str, help: str) -> None:  # noqa: A002
    """Add ``recap estimate`` to the ``recap`` parser."""
    es = sub.add_parser(
        name,
        help=help,
        epilog=_EPILOG,
        description="Units, model calls, tokens and a cost range of a sweep file, before anything is spent.",
    )
    es.add_argument("spec", help="the sweep file (YAML)")


def execute(args: argparse.Namespace, command: str) -> int:
    """Print the plan's units, calls, tokens and cost range; refuses what ``run`` would refuse (keys aside)."""
    spec, _ = load_spec(args.spec)
    with named_source(Path(args.spec).name):
        plan = expand(spec)
        check_models(spec)  # what run refuses before any call, estimate refuses too (keys aside)
        check_plan(plan)
    render_safely(render, plan, estimate(plan))
    return 0
