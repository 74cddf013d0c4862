"""``recap run SPEC`` and ``recap resume RUN_DIR``: check and prepare a sweep, then drive it to the end.

Both refuse bad input with one line before anything is written or spent; the session's exit
status is the driver's (0 all done, 3 a cap stopped it, 4 an infrastructure failure, 130
interrupted).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rich.console import Console

from pipeline.backend import ModelBackend
from pipeline.cli.common import OneLineParser, finite_positive, named_source
from pipeline.cli.console import console, plain, render_safely, styled
from pipeline.cli.locations import check_location
from pipeline.errors import PipelineError, RunFolderError
from pipeline.local_cluster import reap_dead
from pipeline.preflight import check_plan
from pipeline.prepare import Prepared, prepare
from pipeline.resume import repair_run
from pipeline.spec import SweepSpec, check_ray_address_reachable, load_spec, parse_spec, with_overrides
from pipeline.stopping import DEFAULT_GRACE_S
from pipeline.store import RUN_FILE, SPEC_FILE, RunStore
from pipeline.summary import collect, model_label, render
from pipeline.tables import Col, print_fitted
from recap.plural import count

_RUN_EXIT = """\
exit status:
  0    all units done
  2    bad input, the run folder in use by another driver, or the sink lost
       (then recap resume RUN re-runs only what was never written)
  3    a cap stopped it, work remains: recap resume RUN --run-cap USD
  4    a unit ended in an infrastructure failure (provider unreachable, key refused,
       rate-limited too long, a worker kept dying): fix the cause, then retry with
       recap resume RUN
  130  interrupted (Ctrl-C or SIGTERM): continue with recap resume RUN

Ctrl-C once (or SIGTERM): no new unit starts, the episodes in flight finish (up to
--stop-grace seconds), everything is written. Twice: the episodes in flight are cut at once;
the calls they made stay recorded, the resume runs those units again.
A local Ray cluster left running by a driver that was killed (kill -9, out of memory) is
stopped by the next recap run or recap resume, which says so.

A torn last line in the ledger journal (a crash mid-write; recap status names it) is cut by
recap resume RUN --repair (a backup is kept; a corrupt line in the middle is refused).
"""

_RUN_EPILOG = (
    """\
examples:
  recap run examples/demo.yaml --dry-run              check the sweep and show the plan, run nothing
  recap run examples/demo.yaml --workers 8 --run-cap 5
  recap run --progress lines examples/demo.yaml       options go before or after SPEC
  recap run ~/my-sweep.yaml --address auto            join the Ray cluster this machine is in
  recap run examples/demo.yaml --output runs/demo-2   another output folder than the spec's

Running a sweep again on its output folder prints what changed and runs only units without a
result.

"""
    + _RUN_EXIT
)

_RESUME_EPILOG = (
    """\
examples:
  recap resume runs/demo                     finish the remaining units (spec saved in the folder)
  recap resume runs/demo --run-cap 60        continue with a higher run cap
  recap resume --repair runs/demo            cut a torn last ledger line first, then resume
  recap resume runs/demo --retry errors      also re-run units that ended env_error / llm_error
  recap resume s3://bucket/runs/demo --address auto

"""
    + _RUN_EXIT
)


def _run_flags(sp: argparse.ArgumentParser) -> None:
    """The options ``run`` and ``resume`` share: where and how the episodes run."""
    sp.add_argument(
        "--address",
        metavar="ADDRESS",
        help="join an existing Ray cluster (e.g. 10.0.0.5:6379 or auto) instead of starting a local one",
    )
    sp.add_argument("--workers", type=int, metavar="N", help="number of episode workers (overrides the spec's)")
    sp.add_argument("--run-cap", type=float, dest="run_cap", metavar="USD", help="run dollar cap in USD (overrides the spec's)")
    sp.add_argument(
        "--progress",
        choices=("auto", "live", "lines", "off"),
        default="auto",
        help="progress display: live (a terminal), lines (a line every few seconds), off; "
        "auto (default) is live on a terminal, lines otherwise",
    )
    sp.add_argument(
        "--executor",
        choices=("ray", "in-process"),
        default="ray",
        help="where episodes run: ray (default) - one Ray actor per worker; in-process - threads of "
        "this process (no actor start-up, debugger breakpoints work; the sink and the gateways "
        "stay Ray actors)",
    )
    sp.add_argument(
        "--stop-grace",
        type=finite_positive,
        dest="stop_grace",
        default=DEFAULT_GRACE_S,
        metavar="SECONDS",
        help="after a first Ctrl-C (or SIGTERM) no unit starts and the episodes in flight get this long "
        f"to finish before they are cut; a second Ctrl-C cuts them at once (default {DEFAULT_GRACE_S:g})",
    )


def add_parser(sub: argparse._SubParsersAction[OneLineParser], name: str, help: str) -> None:  # noqa: A002
    """Add ``recap run`` or ``recap resume`` (``name``) to the ``recap`` parser."""
    if name == "run":
        r = sub.add_parser(
            "run",
            help=help,
            epilog=_RUN_EPILOG,
            description="Run a sweep file: every (instance, method, model, sampling seed) unit without a result.",
        )
        r.add_argument("spec", help="the sweep file (YAML)")
        _run_flags(r)
        r.add_argument("--output", metavar="DIR", help="output folder or s3:// URI (overrides the spec's)")
        r.add_argument("--dry-run", action="store_true", help="check the spec and show the plan, run nothing")
        return
    rs = sub.add_parser(
        "resume",
        help=help,
        epilog=_RESUME_EPILOG,
        description="Finish a run from the spec saved in its folder; finished units never re-run.",
    )
    rs.add_argument("run_dir", help="the run folder (a path or an s3:// URI)")
    _run_flags(rs)
    rs.add_argument(
        "--repair",
        action="store_true",
        help="first cut a torn last line off the ledger journal (a backup is kept); refuses a corrupt line in the middle",
    )
    rs.add_argument(
        "--retry",
        choices=("infra", "errors"),
        default="infra",
        help="what to run again besides unfinished units: infra (default) - units whose latest attempt failed on "
        "infrastructure; errors - also units that ended env_error or llm_error (a data folder or a param "
        "fixed since); earlier rows are kept, the new attempt gets the next number",
    )


def execute(args: argparse.Namespace, command: str) -> int:
    """Run the parsed ``recap run`` or ``recap resume``; ``command`` (the command line) is recorded with the run."""
    return cmd_run(args, command) if args.cmd == "run" else cmd_resume(args, command)


def plan_rows(prepared: Prepared) -> list[list[str]]:
    """The plan per arm (method x model) and benchmark, in plan order: units, and how many are new,
    unchanged and changed against the run folder's stored plan (a fresh folder: all new)."""
    diff = prepared.diff
    state = {} if diff is None else {**dict.fromkeys(diff.unchanged, "unchanged"), **dict.fromkeys(diff.changed, "changed")}
    counts: dict[tuple[str, str, str], dict[str, int]] = {}
    for u in prepared.plan.units:
        c = counts.setdefault((u.method_label, u.model_label, u.benchmark), {"units": 0, "new": 0, "unchanged": 0, "changed": 0})
        c["units"] += 1
        c[state.get(u.key, "new")] += 1
    doubles = {m.name for m in prepared.spec.models if m.test_double}
    return [
        [arm, model_label(model, model in doubles), bench, *(str(c[k]) for k in ("units", "new", "unchanged", "changed"))]
        for (arm, model, bench), c in counts.items()
    ]


def _print_plan(prepared: Prepared, out: Console) -> None:
    plan = prepared.plan
    models = ", ".join(model_label(m.name, m.test_double) for m in plan.spec.models)
    out.print(plain(f"run {plan.spec.run}: {count(len(plan.units), 'unit')} -> {prepared.store.location}  (models: {models})"))
    cols = (
        Col("arm", "left"),
        Col("model", "left"),
        Col("benchmark", "left"),
        Col("units", drop=1),
        Col("new", drop=4),
        Col("unchanged", drop=2),
        Col("changed", drop=3),
    )
    print_fitted(out, f"plan of run {plan.spec.run}", cols, plan_rows(prepared))
    if prepared.diff is not None:
        d = prepared.diff
        out.print(plain(f"changes since the last start: {d.describe()}"))
        for label, keys in (("new", d.new), ("changed", d.changed)):
            for k in keys[:10]:
                out.print(plain(f"  {label}: {k}"))
            if len(keys) > 10:
                out.print(plain(f"  ... and {len(keys) - 10} more {label}"))


def _execute(prepared: Prepared, args: argparse.Namespace, command: str, backend: ModelBackend | None = None) -> int:
    """Drive the prepared run to its end and print what happened; the session's exit status."""
    from pipeline.driver import Driver  # Ray and the run's services: imported once a run proceeds
    from pipeline.gateway_backend import make_backend

    for reaped in reap_dead():  # a killed driver's local Ray cluster (pipeline.local_cluster)
        print(f"recap: {reaped.describe()}", file=sys.stderr, flush=True)
    backend = backend if backend is not None else make_backend(prepared.spec)
    driver = Driver(
        prepared,
        backend,
        command=command,
        progress=args.progress,
        address=args.address,
        retry=getattr(args, "retry", "infra"),
        executor=args.executor,
        stop_grace_s=args.stop_grace,
    )
    try:
        summary = driver.run()
    except KeyboardInterrupt:  # a third Ctrl-C, or one while Ray was starting
        _interrupted_hint(prepared.store)
        return 130
    report = collect(prepared.store)
    render_safely(render, report)
    out, location = console(), prepared.store.location
    if summary.stopped:
        out.print(
            styled(
                # the spend figure is the summary's above (the ledger journal's), not the one
                # of the moment the cap stopped the run: calls in flight settled after it
                f"stopped: {summary.stopped} (spent {report.spend_line}); {count(summary.not_started, 'unit')} not started, "
                f"{count(summary.budget_stopped, 'episode')} ended budget_exhausted this session",
                "yellow",
            )
        )
        out.print(plain(f"continue with a higher cap: recap resume {location} --run-cap <USD>"))
    if summary.interrupted:
        cut = (
            f" ({count(summary.cut, 'episode')} in flight {'was' if summary.cut == 1 else 'were'} cut and run again on resume)"
            if summary.cut
            else ""
        )
        out.print(styled(f"interrupted{cut}; continue with: recap resume {location}", "yellow"))
    if summary.retried_errors:
        out.print(
            plain(
                f"--retry errors: {count(summary.retried_errors, 'unit')} that had ended in env_error or llm_error "
                "were queued again (their earlier rows are kept)"
            )
        )
    if summary.abandoned:
        text = f"{count(summary.abandoned, 'unit')} gave up after {prepared.spec.max_attempts} failed attempts (see the events table)"
        out.print(styled(text, "red"))
    out.print(plain(f"run folder: {location}   report: recap report {location}"))
    return summary.exit_code()


def _interrupted_hint(store: RunStore) -> None:
    """The line of a session stopped by a raised interrupt: how to continue."""
    if store.exists(RUN_FILE):
        print(f"recap: interrupted; continue with: recap resume {store.location}", file=sys.stderr)
    else:
        print("recap: interrupted before the run started; nothing was written", file=sys.stderr)


def _prepare(spec: SweepSpec, text: str) -> tuple[Prepared, ModelBackend]:
    """(prepared run, model backend); an OS-level failure (an unreadable data file, an output
    store that refuses a listing) is one line too, before anything is written."""
    check_location(spec.output)
    try:
        prepared = prepare(spec, text)
        check_plan(prepared.plan)  # every (task kind, method) builds, renders its demo and opens: before any call
        from pipeline.gateway_backend import make_backend  # once the sweep is accepted (a refusal skips it)

        return prepared, make_backend(spec)
    except OSError as exc:
        detail = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise PipelineError(f"cannot prepare the run in {spec.output}: {detail}") from None


def cmd_run(args: argparse.Namespace, command: str) -> int:
    """``recap run SPEC``: expand and check the spec, print the plan, then run it (``--dry-run`` stops after the
    plan, before any Ray connection or model call)."""
    spec, text = load_spec(args.spec)
    spec = with_overrides(spec, workers=args.workers, run_cap_usd=args.run_cap, output=args.output, address=args.address)
    with named_source(Path(args.spec).name):
        prepared, backend = _prepare(spec, text)
    if not args.dry_run:
        # a host:port address must answer before the driver writes anything (bounded: ray.init
        # on a dead address would retry for minutes)
        check_ray_address_reachable(spec.ray.address)
    _print_plan(prepared, console())
    if args.dry_run:
        return 0
    return _execute(prepared, args, command, backend)


def cmd_resume(args: argparse.Namespace, command: str) -> int:
    """``recap resume RUN_DIR``: continue a run from the spec.yaml saved in its folder (``--repair`` first);
    refuses a folder whose spec names another run than run.json."""
    check_location(args.run_dir)
    store = RunStore(args.run_dir)
    ident = store.require_identity()
    if args.repair:
        console().print(repair_run(store), markup=False, soft_wrap=True)
    text = store.read_text(SPEC_FILE)
    if text is None:
        raise RunFolderError(f"{args.run_dir} has no {SPEC_FILE}; start it again with recap run SPEC")
    spec = parse_spec(text, f"{args.run_dir}/{SPEC_FILE}")
    spec = with_overrides(spec, workers=args.workers, run_cap_usd=args.run_cap, output=args.run_dir, address=args.address)
    if spec.run != ident.run:
        raise RunFolderError(f"{args.run_dir}: {SPEC_FILE} names run {spec.run!r} but run.json names {ident.run!r}")
    with named_source(f"{args.run_dir}/{SPEC_FILE}"):
        prepared, backend = _prepare(spec, text)
    check_ray_address_reachable(spec.ray.address)
    _print_plan(prepared, console())
    return _execute(prepared, args, command, backend)
