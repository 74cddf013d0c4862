"""The ``recap`` command: run, resume, status, estimate, show, sql, report, env.

Every user error is one line on stderr (``recap: error: ...``) and exit status 2, raised before
any model call and before anything is written. Exit status of ``run``/``resume``: 0 when every
unit is done, 3 when work remains (a cap stopped it), 130 when interrupted.
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
    """argparse type: a finite number > 0 (``nan``, ``inf`` and ``-1`` are usage errors)."""
    import math

    try:
        x = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid number: {value!r}") from None
    if not math.isfinite(x) or x <= 0:
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {value!r}")
    return x


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
    exit status 2, instead of a usage block followed by the message."""

    def error(self, message: str) -> "NoReturn":  # type: ignore[override]
        where = self.prog.removeprefix("recap").strip()
        hint = f"recap {where} --help" if where else "recap --help"
        self.exit(EXIT_USAGE, one_line(f"recap: error: {where + ': ' if where else ''}{message} (see {hint})") + "\n")


def _parser() -> argparse.ArgumentParser:
    p = _OneLineParser(prog="recap", description="Run and inspect ReCAP evaluation sweeps.")
    sub = p.add_subparsers(dest="cmd", required=True, metavar="COMMAND")
    sub.add_parser("data", help="list, check or fetch the benchmark data folders (recap data --help)", add_help=False)

    def run_flags(sp: argparse.ArgumentParser) -> None:
        sp.add_argument("--address", help="join an existing Ray cluster (e.g. 10.0.0.5:6379 or auto)")
        sp.add_argument("--workers", type=int, help="number of episode workers")
        sp.add_argument("--run-cap", type=float, dest="run_cap", help="run dollar cap (USD)")
        sp.add_argument("--progress", choices=("auto", "live", "lines", "off"), default="auto")

    r = sub.add_parser("run", help="run a sweep file")
    r.add_argument("spec")
    run_flags(r)
    r.add_argument("--output", help="output folder (overrides the spec's)")
    r.add_argument("--dry-run", action="store_true", help="check the spec and show the plan, run nothing")

    rs = sub.add_parser("resume", help="finish a run after a crash or with a higher cap")
    rs.add_argument("run_dir")
    run_flags(rs)
    rs.add_argument("--repair", action="store_true",
                    help="first cut a torn last line off the ledger journal (a backup is kept); refuses a corrupt line in the middle")

    st = sub.add_parser("status", help="units done/total, success, spend of a run folder")
    st.add_argument("run_dir")

    es = sub.add_parser("estimate", help="units, calls, tokens and a cost range of a sweep file")
    es.add_argument("spec")

    sh = sub.add_parser("show", help="one episode's ReCAP context tree")
    sh.add_argument("run_dir")
    sh.add_argument("episode")

    q = sub.add_parser("sql", help="read-only SQL over a run's tables")
    q.add_argument("run_dir")
    q.add_argument("query")

    rp = sub.add_parser("report", help="build the report of one or more runs", add_help=False)
    rp.add_argument("args", nargs=argparse.REMAINDER)

    env = sub.add_parser("env", help="list, play or replay benchmark instances")
    esub = env.add_subparsers(dest="env_cmd", required=True, metavar="ACTION")
    el = esub.add_parser("list", help="instance ids of a benchmark")
    el.add_argument("bench")
    el.add_argument("selector", nargs="?")
    ep = esub.add_parser("play", help="play an instance by hand")
    ep.add_argument("instance_id")
    ep.add_argument("--step-multiplier", type=_finite_positive, default=4.0)
    er = esub.add_parser("replay", help="replay a recorded Robotouille trajectory")
    er.add_argument("trajectory")
    return p


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
    from pipeline.summary import collect, render

    console = _console()
    backend = backend if backend is not None else _backend(prepared.spec)
    driver = Driver(prepared, backend, command=command, progress=args.progress, address=args.address)
    summary = driver.run()
    _render(render, collect(prepared.store))
    if summary.stopped:
        console.print(_styled(f"stopped: {summary.stopped}; {summary.not_started} units not started, "
                              f"{summary.budget_stopped} episodes ended budget_exhausted this session", "yellow"))
        console.print(_plain(f"continue with a higher cap: recap resume {prepared.store.location} --run-cap <USD>"))
    if summary.interrupted:
        console.print(_styled(f"interrupted; continue with: recap resume {prepared.store.location}", "yellow"))
    if summary.abandoned:
        console.print(_styled(f"{summary.abandoned} units gave up after {prepared.spec.max_attempts} failed attempts (see the events table)", "red"))
    console.print(_plain(f"run folder: {prepared.store.location}   report: recap report {prepared.store.location}"))
    return summary.exit_code()


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
        raise PipelineError(f"cannot read {args.run_dir}: {type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}") from None
    _render(render, report)
    return 0


def cmd_estimate(args: argparse.Namespace) -> int:
    from pipeline.estimate import estimate, render
    from pipeline.spec import load_spec
    from pipeline.units import expand

    spec, _ = load_spec(args.spec)
    plan = expand(spec)
    _render(render, plan, estimate(plan))
    return 0


def cmd_report(argv: list[str]) -> int:
    try:
        from reports.commands import report_main
    except ModuleNotFoundError as exc:
        if exc.name in ("reports", "reports.commands"):
            raise PipelineError("reports are not available (reports.commands is not installed)") from None
        raise
    return int(report_main(argv) or 0)


def dispatch(args: argparse.Namespace, argv: Sequence[str]) -> int:
    command = "recap " + " ".join(argv)
    if args.cmd == "run":
        return cmd_run(args, command)
    if args.cmd == "resume":
        return cmd_resume(args, command)
    if args.cmd == "status":
        return cmd_status(args)
    if args.cmd == "estimate":
        return cmd_estimate(args)
    if args.cmd in ("show", "sql"):
        _check_location(args.run_dir)
    if args.cmd == "show":
        from pipeline.show import show_main

        return show_main(args.run_dir, args.episode, _console())
    if args.cmd == "sql":
        from pipeline.sqlview import sql_main

        return sql_main(args.run_dir, args.query, _console())
    if args.cmd == "env":
        from pipeline import envcmd

        if args.env_cmd == "list":
            return envcmd.list_main(args.bench, args.selector, sys.stdout)
        if args.env_cmd == "play":
            return envcmd.play_main(args.instance_id, sys.stdin, sys.stdout, args.step_multiplier)
        return envcmd.replay_main(args.trajectory, sys.stdout)
    raise AssertionError(args.cmd)


def _local_run_args(args: list[str]) -> list[str]:
    """Object-store run folders among ``args`` replaced by freshly pulled local mirrors (the
    reports package reads local folders)."""
    from pipeline.store import RUN_FILE, RunStore
    from workers.sink import is_uri

    from pipeline.spec import URI_SCHEMES

    out = []
    for a in args:
        if is_uri(a) and a.split("://", 1)[0].lower() in URI_SCHEMES:  # not a query that quotes a URL
            _check_location(a)
        if is_uri(a) and RunStore(a).exists(RUN_FILE):
            from pipeline.mirror import mirror_dir, pull

            local = mirror_dir(a)
            pull(a, local)
            a = str(local)
        out.append(a)
    return out


def cmd_sql_delegated(argv: list[str]) -> int | None:
    """``recap sql ...`` handed whole to reports.commands.sql_main (several run folders,
    --csv/--json, named queries); None when the reports package is not installed."""
    from pipeline.sqlview import _delegate

    delegate = _delegate()
    if delegate is None:
        return None
    return int(delegate(_local_run_args(argv)) or 0)


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    _CHECKED.clear()
    if argv and argv[0] == "data":
        from pipeline.data import data_main

        return data_main(argv[1:], sys.stdout, sys.stderr)
    if argv and argv[0] in ("report", "sql") and not {"-h", "--help"} & set(argv[1:2]):
        try:
            if argv[0] == "report":
                return cmd_report(_local_run_args(argv[1:]))
            code = cmd_sql_delegated(argv[1:])
            if code is not None:
                return code
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
