"""The ``recap`` command: run, resume, status, estimate, show, sql, report, env.

Every user error is one line on stderr (``recap: error: ...``) and exit status 2, raised before
any model call and before anything is written. Exit status of ``run``/``resume``: 0 when every
unit is done, 3 when work remains (a cap stopped it), 4 when a unit ended in an infrastructure
failure, 130 when interrupted. Every command's ``--help`` (stdout, status 0) lists its options
and examples; ``recap`` alone prints its usage line and a hint on stderr, status 2.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, NoReturn

os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")

from pipeline.errors import PipelineError, one_line  # noqa: E402
from pipeline.stopping import DEFAULT_GRACE_S  # noqa: E402
from workers.log_setup import DEFAULT_LEVEL as DEFAULT_LOG_LEVEL  # noqa: E402
from workers.log_setup import LEVEL_VAR as LOG_LEVEL_VAR  # noqa: E402
from workers.log_setup import LEVELS as LOG_LEVELS  # noqa: E402
from workers.log_setup import configure as configure_logging  # noqa: E402

EXIT_USAGE = 2


def _plain(text: str) -> Any:
    """``text`` for a rich console with markup off: user strings (run and model names, paths,
    unit keys) are printed as they are, never read as ``[style]`` tags."""
    from rich.text import Text

    return Text(text)


def _styled(text: str, style: str) -> Any:
    from rich.text import Text

    return Text(text, style=style)


def _finite_positive(value: str) -> float:
    """argparse type: a finite number > 0 (reports.commands.finite_positive's rule)."""
    from reports.commands import finite_positive

    return finite_positive(value)


def _console(stderr: bool = False, *, markup: bool = True) -> Any:
    """A rich console; wide when writing to a file or pipe so tables keep one line per row."""
    from rich.console import Console

    stream = sys.stderr if stderr else sys.stdout
    width = None if getattr(stream, "isatty", lambda: False)() else 200
    return Console(file=stream, highlight=False, width=width, markup=markup)


def _render(render: Any, *args: Any) -> None:
    """``render(*args, console)`` where the rendered text holds user strings (run, method and
    model names, paths) that may read as Rich markup (``[/]`` in an old run's label would raise
    on every ``recap status``): rendered once off screen, and with markup off if that fails."""
    import io

    from rich.console import Console
    from rich.errors import MarkupError

    console = _console()
    try:
        render(*args, Console(file=io.StringIO(), highlight=False, width=console.width))
    except MarkupError:
        console = _console(markup=False)
    render(*args, console)


class _OneLineParser(argparse.ArgumentParser):
    """argparse whose usage errors are one line like every other error (``recap: error: ...``),
    exit status 2, instead of a usage block followed by the message. Help keeps the layout of
    its description and epilog (examples, exit statuses) and goes to stdout."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", argparse.RawDescriptionHelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        where = self.prog.removeprefix("recap").strip()
        hint = f"recap {where} --help" if where else "recap --help"
        self.exit(EXIT_USAGE, one_line(f"recap: error: {where + ': ' if where else ''}{message} (see {hint})") + "\n")


#: the commands in the order ``recap --help`` lists them
COMMANDS = ("run", "resume", "status", "estimate", "show", "sql", "report", "view", "env", "data")

_MAIN_EPILOG = """\
examples:
  recap estimate examples/demo.yaml         units, calls, tokens and a cost range; spends nothing
  recap run examples/demo.yaml              run the sweep (local Ray); prints the run folder
  recap status runs/demo                    done/total, success, spend (also mid-run)
  recap resume runs/demo --run-cap 60       finish after a crash or with a higher cap
  recap sql runs/demo @failure_modes        read-only SQL over the run's tables
  recap report runs/demo                    Markdown/HTML/LaTeX/CSV report under runs/demo/report
  recap view runs/demo                      browse every episode on http://127.0.0.1:8765/

Each command's options and examples: recap COMMAND --help. Every error is one line on stderr.
"""

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

_STATUS_EPILOG = """\
examples:
  recap status runs/demo
  recap status s3://bucket/runs/demo

Works mid-run and after a crash; names unreadable part files and a torn ledger line.
exit status: 0 shown; 2 not a run folder (or unreadable)
"""

_ESTIMATE_EPILOG = """\
examples:
  recap estimate examples/real-model.yaml
  recap estimate examples/demo.yaml

Reads the sweep file only: no model is called, nothing is written.
exit status: 0 shown; 2 bad sweep file
"""

_SHOW_EPILOG = """\
examples:
  recap show runs/demo 3f9c0a1b2d4e5f60       an episode id or a unit id (its latest attempt)
  recap show runs/demo 3f9c                   an unambiguous prefix of either

Find ids with: recap sql runs/demo "select episode_id, unit_id, arm, success from terminal"
exit status: 0 shown; 2 unknown or ambiguous EPISODE, or not a run folder
"""

_ENV_EPILOG = """\
examples:
  recap env list blocksworld 4
  recap env play blocksworld/3@1
  recap env replay trajectory.json

No model is involved. Each action's options and examples: recap env ACTION --help.
"""

_ENV_LIST_EPILOG = """\
examples:
  recap env list blocksworld                  every instance id
  recap env list blocksworld 4                the ids of 4-block problems
  recap env list robotouille asynchronous
  recap env list alfworld heat

The ids go to stdout, one a line, and their count to stderr. exit status: 0 ok; 2 unknown
benchmark or selector, or its data is missing (recap data --help)
"""

_ENV_PLAY_EPILOG = """\
examples:
  recap env play blocksworld/3@1
  recap env play robotouille/synchronous/0_cheese_sandwich@42 --step-multiplier 2

Type an action (any letter case) or its number in the list; quit, exit or q to stop.
exit status: 0 played; 2 unknown instance or missing data
"""

_ENV_REPLAY_EPILOG = """\
examples:
  recap env replay trajectory.json

exit status: 0 every observation identical; 1 a difference (printed); 2 unreadable trajectory
"""


def _parser() -> argparse.ArgumentParser:
    p = _OneLineParser(prog="recap", description="Run and inspect ReCAP evaluation sweeps.", epilog=_MAIN_EPILOG)
    p.add_argument(
        "--log-level",
        choices=LOG_LEVELS,
        default=DEFAULT_LOG_LEVEL,
        help="diagnostic lines on stderr (and in the Ray workers' logs) from this level up; "
        "accepted before or after any command (default: warning, or $RECAP_LOG_LEVEL)",
    )
    sub = p.add_subparsers(
        dest="cmd",
        required=True,
        metavar="COMMAND",
        title="commands",
        help="one of the commands below; recap COMMAND --help for its options and examples",
    )

    def run_flags(sp: argparse.ArgumentParser) -> None:
        sp.add_argument(
            "--address",
            metavar="ADDRESS",
            help="join an existing Ray cluster (e.g. 10.0.0.5:6379 or auto) instead of starting a local one",
        )
        sp.add_argument("--workers", type=int, metavar="N", help="number of episode workers (overrides the spec's)")
        sp.add_argument(
            "--run-cap", type=float, dest="run_cap", metavar="USD", help="run dollar cap in USD (overrides the spec's)"
        )
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
            type=_finite_positive,
            dest="stop_grace",
            default=DEFAULT_GRACE_S,
            metavar="SECONDS",
            help="after a first Ctrl-C (or SIGTERM) no unit starts and the episodes in flight get this long "
            f"to finish before they are cut; a second Ctrl-C cuts them at once (default {DEFAULT_GRACE_S:g})",
        )

    r = sub.add_parser(
        "run",
        help="run a sweep file",
        epilog=_RUN_EPILOG,
        description="Run a sweep file: every (instance, method, model, seed) unit without a result.",
    )
    r.add_argument("spec", help="the sweep file (YAML)")
    run_flags(r)
    r.add_argument("--output", metavar="DIR", help="output folder or s3:// URI (overrides the spec's)")
    r.add_argument("--dry-run", action="store_true", help="check the spec and show the plan, run nothing")

    rs = sub.add_parser(
        "resume",
        help="finish a run after a crash or with a higher cap",
        epilog=_RESUME_EPILOG,
        description="Finish a run from the spec saved in its folder; finished units never re-run.",
    )
    rs.add_argument("run_dir", help="the run folder (a path or an s3:// URI)")
    run_flags(rs)
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

    st = sub.add_parser(
        "status",
        help="units done/total, success, spend of a run folder",
        epilog=_STATUS_EPILOG,
        description="Units done/total, success, spend and problems of a run folder.",
    )
    st.add_argument("run_dir", help="the run folder (a path or an s3:// URI)")

    es = sub.add_parser(
        "estimate",
        help="units, calls, tokens and a cost range of a sweep file",
        epilog=_ESTIMATE_EPILOG,
        description="Units, model calls, tokens and a cost range of a sweep file, before anything is spent.",
    )
    es.add_argument("spec", help="the sweep file (YAML)")

    sh = sub.add_parser(
        "show",
        help="one episode's ReCAP context tree",
        epilog=_SHOW_EPILOG,
        description="One episode's ReCAP context tree (or a flat method's actions) in the terminal.",
    )
    sh.add_argument("run_dir", help="the run folder (a path or an s3:// URI)")
    sh.add_argument("episode", help="an episode id, a unit id (its latest attempt), or an unambiguous prefix")

    # sql, report and view are read by the reports package (see main); these entries list them in recap --help
    sub.add_parser(
        "sql", help="read-only SQL over the tables of one or more run folders (--csv, --json, --file, @NAME)", add_help=False
    )
    sub.add_parser("report", help="build the report (Markdown, HTML, LaTeX, CSV) of one or more runs", add_help=False)
    sub.add_parser("view", help="browse every episode of one or more runs in a local web viewer (read-only)", add_help=False)

    env = sub.add_parser(
        "env",
        help="list, play or replay benchmark instances (no model)",
        epilog=_ENV_EPILOG,
        description="Look at the benchmarks without any model.",
    )
    esub = env.add_subparsers(
        dest="env_cmd",
        required=True,
        metavar="ACTION",
        title="actions",
        help="one of the actions below; recap env ACTION --help for its options and examples",
    )
    el = esub.add_parser(
        "list",
        help="instance ids of a benchmark",
        epilog=_ENV_LIST_EPILOG,
        description="The instance ids of a benchmark that a sweep file can name.",
    )
    el.add_argument("bench", help="blocksworld, robotouille or alfworld")
    el.add_argument(
        "selector", nargs="?", help="only the ids it selects: a size (blocksworld), a split or task (robotouille, alfworld)"
    )
    ep = esub.add_parser(
        "play",
        help="play an instance by hand",
        epilog=_ENV_PLAY_EPILOG,
        description="Play an instance by hand: see the observation, type actions, watch the step count.",
    )
    ep.add_argument("instance_id", help="an instance id as recap env list prints it (e.g. blocksworld/3@1)")
    ep.add_argument(
        "--step-multiplier",
        type=_finite_positive,
        default=4.0,
        metavar="X",
        help="step cap = X times the optimal plan's length (default 4; ALFWorld's cap is fixed)",
    )
    er = esub.add_parser(
        "replay",
        help="replay a recorded Robotouille trajectory",
        epilog=_ENV_REPLAY_EPILOG,
        description="Re-run a recorded Robotouille trajectory on our engine and compare every observation.",
    )
    er.add_argument("trajectory", help="the recorded trajectory (JSON)")

    sub.add_parser("data", help="list, check or fetch the benchmark data folders (recap data --help)", add_help=False)
    return p


def command_parsers() -> dict[tuple[str, ...], argparse.ArgumentParser]:
    """The parser that reads each command's arguments (and prints its ``--help``), by command
    path: ``()`` is ``recap`` itself, ``("env", "list")`` is ``recap env list``. ``sql``,
    ``report`` and ``view`` are the reports package's parsers; ``data`` is left out
    (:mod:`pipeline.data` builds its own)."""
    found: dict[tuple[str, ...], argparse.ArgumentParser] = {}

    def walk(path: tuple[str, ...], parser: argparse.ArgumentParser) -> None:
        found[path] = parser
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, child in action.choices.items():
                    walk((*path, name), child)

    walk((), _parser())
    del found[("data",)]
    from reports.commands import _report_parser, _sql_parser
    from reports.webview.server import view_parser

    found[("sql",)], found[("report",)], found[("view",)] = _sql_parser(), _report_parser(), view_parser()
    return found


# --------------------------------------------------------------------------------------------
def _backend(spec: Any) -> Any:
    from pipeline.gateway_backend import make_backend

    return make_backend(spec)


@contextmanager
def _named(source: str) -> Iterator[None]:
    """Prefix spec and preflight errors with the sweep file they come from."""
    from pipeline.errors import PreflightError, SpecError

    try:
        yield
    except (SpecError, PreflightError) as exc:
        msg = str(exc)
        if msg.startswith(source + ":"):
            raise
        raise type(exc)(f"{source}: {msg}") from None


def _print_plan(prepared: Any, console: Any) -> None:
    from pipeline.summary import model_label

    plan = prepared.plan
    models = ", ".join(model_label(m.name, m.test_double) for m in plan.spec.models)
    console.print(_plain(f"run {plan.spec.run}: {len(plan.units)} units -> {prepared.store.location}  (models: {models})"))
    if prepared.diff is not None:
        d = prepared.diff
        console.print(_plain(f"changes since the last start: {d.describe()}"))
        for label, keys in (("new", d.new), ("changed", d.changed)):
            for k in keys[:10]:
                console.print(_plain(f"  {label}: {k}"))
            if len(keys) > 10:
                console.print(_plain(f"  ... and {len(keys) - 10} more {label}"))


def _execute(prepared: Any, args: argparse.Namespace, command: str, backend: Any = None) -> int:
    from pipeline.driver import Driver
    from pipeline.local_cluster import reap_dead
    from pipeline.summary import collect, render

    console = _console()
    for reaped in reap_dead():  # a killed driver's local Ray cluster (pipeline.local_cluster)
        print(f"recap: {reaped.describe()}", file=sys.stderr, flush=True)
    backend = backend if backend is not None else _backend(prepared.spec)
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
    _render(render, report)
    if summary.stopped:
        console.print(
            _styled(
                # the spend figure is the summary's above (the ledger journal's), not the one
                # of the moment the cap stopped the run: calls in flight settled after it
                f"stopped: {summary.stopped} (spent {report.spend_line}); {summary.not_started} units not started, "
                f"{summary.budget_stopped} episodes ended budget_exhausted this session",
                "yellow",
            )
        )
        console.print(_plain(f"continue with a higher cap: recap resume {prepared.store.location} --run-cap <USD>"))
    if summary.interrupted:
        cut = f" ({summary.cut} episodes in flight were cut and run again on resume)" if summary.cut else ""
        console.print(_styled(f"interrupted{cut}; continue with: recap resume {prepared.store.location}", "yellow"))
    if summary.retried_errors:
        console.print(
            _plain(
                f"--retry errors: {summary.retried_errors} units that had ended in env_error or llm_error "
                "were queued again (their earlier rows are kept)"
            )
        )
    if summary.abandoned:
        console.print(
            _styled(
                f"{summary.abandoned} units gave up after {prepared.spec.max_attempts} failed attempts (see the events table)",
                "red",
            )
        )
    console.print(_plain(f"run folder: {prepared.store.location}   report: recap report {prepared.store.location}"))
    return summary.exit_code()


def _interrupted_hint(store: Any) -> None:
    """The line of a session stopped by a raised interrupt: how to continue."""
    from pipeline.store import RUN_FILE

    if store.exists(RUN_FILE):
        print(f"recap: interrupted; continue with: recap resume {store.location}", file=sys.stderr)
    else:
        print("recap: interrupted before the run started; nothing was written", file=sys.stderr)


_CHECKED: set[str] = set()


def _check_location(location: str) -> None:
    """An object-store run folder must answer (bounded in time) before anything touches it;
    checked once per location and command (``main`` forgets the checks of the last command)."""
    from pipeline.spec import check_output_location

    if location not in _CHECKED:
        check_output_location(location)
        _CHECKED.add(location)


def _prepare(spec: Any, text: str) -> tuple[Any, Any]:
    """(prepared run, model backend); an OS-level failure (an unreadable data file, an output
    store that refuses a listing) is one line too, before anything is written."""
    from pipeline.driver import prepare

    _check_location(spec.output)
    try:
        prepared = prepare(spec, text)
        from pipeline.preflight import check_plan

        check_plan(prepared.plan)  # every (task kind, method) builds, renders its demo and opens: before any call
        return prepared, _backend(spec)
    except OSError as exc:
        detail = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise PipelineError(f"cannot prepare the run in {spec.output}: {detail}") from None


def _check_ray_address(spec: Any) -> None:
    """A cluster address given as host:port must answer before the driver writes anything
    (bounded: ``ray.init`` on a dead address would retry for minutes)."""
    from pipeline.spec import check_ray_address_reachable

    check_ray_address_reachable(spec.ray.address)


def cmd_run(args: argparse.Namespace, command: str) -> int:
    """``recap run SPEC``: expand and check the spec, print the plan, then run it (``--dry-run`` stops after the
    plan, before any Ray connection or model call)."""
    from pipeline.spec import load_spec, with_overrides

    spec, text = load_spec(args.spec)
    spec = with_overrides(spec, workers=args.workers, run_cap_usd=args.run_cap, output=args.output, address=args.address)
    with _named(Path(args.spec).name):
        prepared, backend = _prepare(spec, text)
    if not args.dry_run:
        _check_ray_address(spec)
    console = _console()
    _print_plan(prepared, console)
    if args.dry_run:
        return 0
    return _execute(prepared, args, command, backend)


def cmd_resume(args: argparse.Namespace, command: str) -> int:
    """``recap resume RUN_DIR``: continue a run from the spec.yaml saved in its folder (``--repair`` first);
    refuses a folder whose spec names another run than run.json."""
    from pipeline.errors import RunFolderError
    from pipeline.spec import parse_spec, with_overrides
    from pipeline.store import SPEC_FILE, RunStore

    _check_location(args.run_dir)
    store = RunStore(args.run_dir)
    ident = store.require_identity()
    if args.repair:
        from pipeline.resume import repair_run

        _console().print(repair_run(store), markup=False, soft_wrap=True)
    text = store.read_text(SPEC_FILE)
    if text is None:
        raise RunFolderError(f"{args.run_dir} has no {SPEC_FILE}; start it again with recap run SPEC")
    spec = parse_spec(text, f"{args.run_dir}/{SPEC_FILE}")
    spec = with_overrides(spec, workers=args.workers, run_cap_usd=args.run_cap, output=args.run_dir, address=args.address)
    if spec.run != ident.run:
        raise RunFolderError(f"{args.run_dir}: {SPEC_FILE} names run {spec.run!r} but run.json names {ident.run!r}")
    with _named(f"{args.run_dir}/{SPEC_FILE}"):
        prepared, backend = _prepare(spec, text)
    _check_ray_address(spec)
    _print_plan(prepared, _console())
    return _execute(prepared, args, command, backend)


def cmd_status(args: argparse.Namespace) -> int:
    """``recap status RUN_DIR``: the run's summary table; a damaged folder is one error line, never a traceback."""
    from pipeline.store import RunStore
    from pipeline.summary import collect, render

    _check_location(args.run_dir)
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
    _render(render, report)
    return 0


def cmd_estimate(args: argparse.Namespace) -> int:
    """``recap estimate SPEC``: the plan and its expected cost, without connecting to Ray or calling any model."""
    from pipeline.estimate import estimate, render
    from pipeline.preflight import check_models, check_plan
    from pipeline.spec import load_spec
    from pipeline.units import expand

    spec, _ = load_spec(args.spec)
    with _named(Path(args.spec).name):
        plan = expand(spec)
        check_models(spec)  # what run refuses before any call, estimate refuses too (keys aside)
        check_plan(plan)
    _render(render, plan, estimate(plan))
    return 0


def cmd_report(argv: list[str]) -> int:
    """``recap report ...``: handed to the reports package (object-store run folders pulled to a local copy first)."""
    from reports.commands import report_main

    return int(report_main(argv, resolve_run=_local_run_dir) or 0)


def cmd_view(argv: list[str]) -> int:
    """``recap view``: the reports package's web viewer (local run folders only)."""
    from reports.webview.server import view_main

    return int(view_main(argv) or 0)


def dispatch(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """Run the parsed subcommand (everything except data/report/view, which ``main`` hands off first); the
    command line is recorded with the run."""
    command = "recap " + " ".join(argv)
    if args.cmd == "run":
        return cmd_run(args, command)
    if args.cmd == "resume":
        return cmd_resume(args, command)
    if args.cmd == "status":
        return cmd_status(args)
    if args.cmd == "estimate":
        return cmd_estimate(args)
    if args.cmd == "show":
        _check_location(args.run_dir)
        from pipeline.show import show_main

        return show_main(args.run_dir, args.episode, _console())
    if args.cmd == "env":
        from pipeline import envcmd

        if args.env_cmd == "list":
            return envcmd.list_main(args.bench, args.selector, sys.stdout)
        if args.env_cmd == "play":
            return envcmd.play_main(args.instance_id, sys.stdin, sys.stdout, args.step_multiplier)
        return envcmd.replay_main(args.trajectory, sys.stdout)
    raise AssertionError(args.cmd)


def _local_run_dir(arg: str) -> str:
    """One run-folder argument of ``recap sql`` / ``recap report`` as a local folder: an object-store
    run is pulled to its local mirror first. The reports package calls this for run-folder arguments
    only (never for a query, a title or an output folder); its errors are one line (RunDirError)."""
    from pipeline.spec import URI_SCHEMES
    from reports.views import RunDirError
    from workers.sink import is_uri

    if not is_uri(arg):
        return arg
    scheme = arg.split("://", 1)[0].lower()
    if scheme not in URI_SCHEMES:
        raise RunDirError(
            f"{arg} is not a run folder: unknown URI scheme {scheme!r} (a local folder or {', '.join(s + '://' for s in URI_SCHEMES)})"
        )
    try:
        _check_location(arg)
        from pipeline.store import RUN_FILE, RunStore

        if not RunStore(arg).exists(RUN_FILE):
            raise RunDirError(f"{arg} is not a run folder (no {RUN_FILE})")
        from pipeline.mirror import mirror_dir, pull

        local = mirror_dir(arg)
        pull(arg, local)
        return str(local)
    except RunDirError:
        raise
    except PipelineError as exc:
        raise RunDirError(str(exc)) from None
    except Exception as exc:  # a URI pyarrow cannot parse or reach: one line, never a traceback
        detail = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise RunDirError(f"cannot read run folder {arg}: {detail}") from None


def cmd_sql(argv: list[str]) -> int:
    """``recap sql ...`` handed whole to reports.commands.sql_main (several run folders,
    --csv/--json, named queries); object-store run folders are pulled to a local copy first."""
    from reports.commands import sql_main

    return int(sql_main(argv, resolve_run=_local_run_dir) or 0)


def _take_log_level(argv: list[str]) -> str | None:
    """Remove ``--log-level LEVEL`` (or ``--log-level=LEVEL``) from ``argv`` wherever it stands
    (before or after the command: every command accepts it) and return the level."""
    level = None
    for i, arg in enumerate(argv):
        if arg == "--":
            break
        if arg == "--log-level" or arg.startswith("--log-level="):
            if "=" in arg:
                level, drop = arg.split("=", 1)[1], 1
            elif i + 1 < len(argv):
                level, drop = argv[i + 1], 2
            else:
                raise PipelineError(f"--log-level needs a level: {', '.join(LOG_LEVELS)}")
            if level.lower() not in LOG_LEVELS:
                raise PipelineError(f"--log-level: unknown level {level!r}; one of {', '.join(LOG_LEVELS)}")
            del argv[i : i + drop]
            break
    return level


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``recap``: returns the exit status (see the module docstring) instead of raising, so user
    errors stay one line."""
    argv = list(sys.argv[1:] if argv is None else argv)
    _CHECKED.clear()
    try:
        level = _take_log_level(argv)
    except PipelineError as exc:
        print(f"recap: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    configure_logging(level or os.environ.get(LOG_LEVEL_VAR, "").lower() or DEFAULT_LOG_LEVEL)
    if argv and argv[0] == "data":
        from pipeline.data import data_main

        return data_main(argv[1:], sys.stdout, sys.stderr)
    if not argv:
        usage = _parser().format_usage().strip()
        print(f"{usage}  (COMMAND: {', '.join(COMMANDS)}; see recap --help)", file=sys.stderr)
        return EXIT_USAGE
    if argv[0] in ("report", "sql", "view"):  # --help included: the reports package's parsers say it all
        try:
            if argv[0] == "view":
                return cmd_view(argv[1:])
            if argv[0] == "report":
                return cmd_report(argv[1:])
            return cmd_sql(argv[1:])
        except PipelineError as exc:
            print(f"recap: error: {exc}", file=sys.stderr)
            return EXIT_USAGE
    args = _parser().parse_args(argv)
    try:
        return dispatch(args, argv)
    except PipelineError as exc:
        print(f"recap: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("recap: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
