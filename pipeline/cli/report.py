"""``recap report RUN_DIR ...``: build a report over run folders and write it into a folder of its own.

Exit status: 0 written; 1 a problem with the runs' data or the options; 2 bad usage, a folder
that is not a run folder (no run.json), or an output folder holding files a report did not
write (nothing is written then). Options may come before, between or after the run folders
(``parse_intermixed_args``); every positional is a run folder.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TextIO

from pipeline.cli.common import EXIT_USAGE, CommandParser, HelpExit, UsageError, error_line
from pipeline.cli.locations import Resolver, local_run_dir, run_folders
from recap.plural import count
from reports.build import FORMATS, ReportOptions, build_report, parse_formats, write_report
from reports.output_folder import OutputFolderError, check_report_folder
from reports.viewer import DEFAULT_EPISODES
from reports.views import ReportError, RunDirError

_EPILOG = """examples:
  recap report runs/demo                            all formats under runs/demo/report
  recap report runs/demo --format md,html --title "Demo sweep"
  recap report runs/a runs/b --out reports/ab       two runs in one report (--out required)
  recap report runs/demo --episodes 3f9c0a1b,77d2e0aa --format html
  recap report --viewer-max 0 runs/demo             options go before or after the run folders
  recap report runs/paper-main-robotouille runs/paper-main-alfworld --paper --out reports/paper
                                                    only the paper's tables (examples/paper/)

Writes only under the output folder (RUN_DIR/report or --out), and only into a new or empty
folder or one that holds an earlier report: a folder with any other file is refused.
exit status: 0 written; 1 a problem with the run folders' data or the option values; 2 bad usage,
a folder that is not a run folder (no run.json), or an output folder with other files in it
"""


def parser(out: TextIO | None = None) -> CommandParser:
    """The ``recap report`` parser (``out``: where ``--help`` goes)."""
    p = CommandParser(
        prog="recap report",
        out=out,
        epilog=_EPILOG,
        description="Write a report (Markdown, HTML, LaTeX, CSV) over one or more run folders.",
    )
    p.add_argument("run_dirs", nargs="+", metavar="RUN_DIR", help="run folder(s); several are reported together")
    p.add_argument("--out", metavar="DIR", help="output folder (default: RUN_DIR/report for one run; required for several)")
    p.add_argument(
        "--format",
        default=",".join(FORMATS),
        metavar="LIST",
        help=f"comma-separated formats among {','.join(FORMATS)} (default: all)",
    )
    p.add_argument("--episodes", metavar="IDS", help="comma-separated episode ids to show in the HTML viewer (default: a sample)")
    p.add_argument(
        "--viewer-max",
        type=int,
        default=DEFAULT_EPISODES,
        metavar="N",
        help=f"episodes in the viewer sample (default {DEFAULT_EPISODES}; 0 = none)",
    )
    p.add_argument("--title", default="recap-eval report", metavar="TEXT", help="report title (default: recap-eval report)")
    p.add_argument("--paper", action="store_true", help="only the paper section: the ReCAP paper's tables beside ours")
    return p


def _write(argv: Sequence[str], out: TextIO, resolve_run: Resolver | None) -> tuple[Path, list[Path], tuple[str, ...], list[str]]:
    """Parse, check, build and write the report: (output folder, files written, formats, warning lines)."""
    args = parser(out).parse_intermixed_args(list(argv))
    formats = parse_formats(args.format)
    if args.viewer_max < 0:
        raise ReportError("--viewer-max must be >= 0")
    if args.out is None and len(args.run_dirs) > 1:
        raise ReportError("--out is required when reporting several run folders")
    if args.out is not None and "://" in args.out:
        raise UsageError(f"recap report: --out must be a local folder, got {args.out}")
    run_dirs = run_folders(args.run_dirs, resolve_run)
    out_dir = Path(args.out) if args.out else Path(run_dirs[0]) / "report"
    check_report_folder(out_dir)
    episodes = tuple(e.strip() for e in args.episodes.split(",") if e.strip()) if args.episodes else None
    options = ReportOptions(
        formats=formats, episodes=episodes, viewer_max=args.viewer_max, title=args.title, paper_only=args.paper
    )
    report = build_report(run_dirs, options)
    written = write_report(report, out_dir, formats)
    return out_dir, written, formats, [s.line() for s in report.skipped]


def report_main(
    argv: Sequence[str],
    *,
    stdout: TextIO | None = None,
    stderr: TextIO | None = None,
    resolve_run: Resolver | None = None,
) -> int:
    """``recap report``: build and write the report (to RUN_DIR/report unless ``--out``); exit 0, 1 for a problem
    with the runs or options, 2 for bad usage and for a folder that is not a run folder.

    Writes only under the output folder, and only into a new or empty one or one that holds an earlier
    report (:func:`reports.output_folder.check_report_folder`); ``resolve_run`` makes each run-folder argument local."""
    out, err = stdout or sys.stdout, stderr or sys.stderr
    try:
        out_dir, written, formats, skipped = _write(argv, out, resolve_run)
    except HelpExit as exc:
        return exc.status
    except UsageError as exc:
        print(error_line("report", exc), file=err)
        return EXIT_USAGE
    except (RunDirError, OutputFolderError) as exc:
        print(error_line("report", exc), file=err)
        return EXIT_USAGE
    except ReportError as exc:
        print(error_line("report", exc), file=err)
        return 1
    except OSError as exc:
        print(
            error_line("report", f"cannot write the report: {exc.strerror or type(exc).__name__}: {exc.filename or ''}"), file=err
        )
        return 1
    for line in skipped:
        print(f"warning: {line}", file=err)
    print(f"wrote {count(len(written), 'file')} to {out_dir} ({', '.join(formats)})", file=out)
    for name in ("report.html", "report.md"):
        if (out_dir / name).exists() and name.split(".")[1] in formats:
            print(f"  {out_dir / name}", file=out)
    return 0


def main(argv: list[str]) -> int:
    """``recap report ...``: object-store run folders are pulled to a local copy first."""
    return report_main(argv, resolve_run=local_run_dir)
