"""``recap estimate SPEC``: the plan and its expected cost, without connecting to Ray or calling any model
(``--probe``: the models the sweep serves itself are deployed briefly to measure their tokens/s)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

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
  recap estimate examples/served/cross-model-vllm.yaml --probe --address auto

Reads the sweep file only: no model is called, nothing is written. What a run would still
need on this machine (images, the Docker daemon) is listed under the estimate, not refused.
A model the sweep serves itself is priced by its replica-hours at serve.tokens_per_s; --probe
measures that figure for the served models without it (deployed on Ray, a few requests, then
taken down: the one case where estimate calls a model).
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
    es.add_argument(
        "--probe",
        action="store_true",
        help="deploy the served models without serve.tokens_per_s, measure their output tokens/s, take them down",
    )
    es.add_argument("--address", default=None, help="the Ray cluster a probe deploys on (default: a local one)")


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
        measured = None
        if args.probe:
            with slow_notice("probing the served models' tokens/s (deploying them on Ray)"):
                measured = _probe(spec, args.address)
    with slow_notice(f"measuring {count(instances_to_measure(plan), 'instance')}"):
        groups = estimate(plan, measured)
    render_safely(render, plan, groups, needs)
    return 0


def _probe(spec: Any, address: str | None) -> dict[str, Any]:
    """The tokens/s of the served models the sweep gives no figure for (pipeline.serving.throughput)."""
    labels = [m.name for m in spec.models if m.serve is not None and m.serve.tokens_per_s is None]
    if not labels:
        return {}
    from pipeline.raysetup import init_ray, shutdown_ray  # lazy: Ray loads only for a probe
    from pipeline.serving.checks import check_serving
    from pipeline.serving.throughput import probe

    check_serving(spec)  # the engine installed, the weights here: refused in one line otherwise
    started = init_ray(spec.ray, address)
    try:
        return probe(spec, labels)
    finally:
        if started:
            shutdown_ray()
