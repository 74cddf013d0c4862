"""``recap estimate SPEC``: the plan and its expected cost, without connecting to Ray or calling any model."""

from __future__ import annotations

import argparse
from pathlib import Path

from pipeline.cli.common import OneLineParser, named_source
from pipeline.cli.console import render_safely
from pipeline.cli.notice import slow_notice
from pipeline.estimate import estimate, instances_to_measure, render
from pipeline.preflight import check_models, check_plan
from pipeline.spec import load_spec
from pipeline.units import expand
from recap.plural import count

_EPILOG = """\
examples:
  recap estimate examples/real-model.yaml
  recap estimate examples/demo.yaml

Reads the sweep file only: no model is called, nothing is written. What a run would still
need on this machine (images, the Docker daemon) is listed under the estimate, not refused.
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
    """Print the plan's units, calls, tokens and cost range; refuses what ``run`` would refuse (keys
    aside, and what this machine still lacks for a run - images, a daemon - which it lists instead:
    an estimate spends nothing). A step that runs over two seconds says so on stderr."""
    with slow_notice("reading the sweep file and listing its instances"):
        spec, _ = load_spec(args.spec)
    needs: list[str] = []
    with named_source(Path(args.spec).name):
        with slow_notice("listing the plan's units"):
            plan = expand(spec)
        with slow_notice("checking the models (loading litellm)"):
            check_models(spec)  # what run refuses before any call, estimate refuses too (keys aside)
        with slow_notice("checking that every unit can start its episode"):
            check_plan(plan, needs)
    with slow_notice(f"measuring {count(instances_to_measure(plan), 'instance')}"):
        groups = estimate(plan)
    render_safely(render, plan, groups, needs)
    return 0
