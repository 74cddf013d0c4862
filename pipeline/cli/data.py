"""``recap data``: where the benchmark data is, whether it is intact, and how to get it.

The data never lives in this repository. Three benchmark folders exist: ``robotouille``,
``alfworld`` (ALFWorld games, game-file version 2.1.1: the primary folder) and ``alfworld-2.1.2``
(the same 134 games re-released in 2.1.2 wording, with walkthroughs; optional).

* ``recap data list [BENCH] [--data-dir DIR]`` - every place a benchmark's folder is looked for,
  in order, what each holds, and which one is used. The order is the one rule of
  :mod:`workers.envs.data_paths`, the same for the library, ``recap env``, ``recap run`` and the
  scripts: ``--data-dir``/``data_dir=``, the environment variable (``ROBOTOUILLE_DATA``,
  ``ALFWORLD_DATA``), the upstream project's own cache (ALFWorld: ``~/.cache/alfworld``, what
  ``alfworld-download`` writes), recap-eval's cache (``$RECAP_EVAL_CACHE/data/<bench>``, default
  ``~/.cache/recap-eval/data/<bench>``: where ``fetch`` writes), ``<checkout>/../shared/data/<bench>``.
  ``alfworld-2.1.2`` keeps its own rule (:func:`workers.envs.alfworld.games.resolve_data_dir_2_1_2`):
  ``--data-dir``, ``ALFWORLD_DATA_2_1_2``, else the folder ``alfworld-2.1.2`` next to the ALFWorld
  folder in use (both caches and ``../shared/data`` put it there).
* ``recap data check [BENCH] [--data-dir DIR]`` - verifies each folder against the sha256
  manifest this repository carries (``pipeline/manifests/<bench>.sha256``, ``sha256sum`` format:
  metadata, not data; Robotouille's generated instances may match ``robotouille-generated.sha256``
  instead, see below); one line per benchmark: path, files checked, OK / N missing / N mismatched.
* ``recap data fetch [BENCH] [--mirror URL_OR_DIR] [--dest DIR]`` - downloads what can be
  downloaded, verifies every file against the manifest, generates what is generated
  (Robotouille's instances) and verifies it too, and only then moves the folder into
  place (staged in a hidden folder next to the destination, renamed at the end; a failure
  removes the stage, so no half-written folder is ever left). Default destination:
  recap-eval's cache; ``--dest`` names the folder for one benchmark, or the parent of the three
  folders when no benchmark is named. A destination that exists is verified, not overwritten.
* ``recap data images swebench-verified [SELECTOR ...] [--pull | --build] [--workers N] [--dry-run]``
  - the SWE-bench harness's per-instance images the selected instances lack (selectors as
  ``recap env list swe-verified`` takes them; default all): listed, pulled from Docker Hub
  through the Docker SDK, or built with the harness itself, N at a time, one line per image
  (:mod:`workers.envs.swe_verified.get_images`). Exit 0 when every selected instance has its
  image at the end, 1 when some are missing or failed, 2 for bad usage.

Sources (``--mirror`` replaces the base of every URL below with a folder or a URL prefix holding
the same file names; ``file://`` URLs work). Each benchmark declares its folders, their file
groups and these sources itself (``Benchmark.data_folders``: ``workers/envs/<bench>/data_folders.py``);
this command works on whatever the registered benchmarks declare:

* Robotouille: the archive of the upstream repository at the pinned commit,
  ``https://github.com/portal-cornell/robotouille/archive/<commit>.tar.gz``; only the data paths
  the manifest lists are extracted (``LICENSE``, ``domain/``, ``environments/``, ``agents/``,
  ``conf/``), never code.
* ALFWorld 2.1.1: ALFWorld's release archives ``json_2.1.1_json.zip`` (traj_data.json),
  ``json_2.1.1_pddl.zip`` (initial_state.pddl), ``json_2.1.1_tw-pddl.zip`` (game.tw-pddl), the
  URLs of ALFWorld 0.3.x's ``alfworld-download``, plus ``logic/alfred.pddl`` and
  ``logic/alfred.twl2`` as shipped in alfworld 0.3.5's package data (alfworld 0.4.2 ships the
  2.1.2 wording). Only the 134 evaluation games are extracted.
* ``recap-release`` (not a benchmark: the authors' prompt and demonstration files, read only by
  ``prompts: release`` runs, :mod:`workers.release`): the files its manifest lists, taken with
  ``git archive`` from the repository ``https://github.com/ReCAP-Stanford/ReCAP.git`` at the pinned
  commit (a one-commit partial fetch, so the release's large data files are never downloaded), or
  from ``--mirror``, which here names the repository itself (a local clone, bare or not, or a git
  URL). It is not part of ``all``: name it.
* ``swebench-verified`` (SWE-bench Verified, benchmark ``swe-verified``): not downloaded file by
  file but loaded: ``princeton-nlp/SWE-bench_Verified`` (split ``test``) through the ``datasets``
  library, or ``--from FILE`` (a local Parquet or JSONL copy); checked (500 records unless
  ``--subset``, recorded as a subset) and stored as ``instances.jsonl`` + ``SOURCE.json`` with the
  folder's own ``MANIFEST.sha256`` (:mod:`workers.envs.swe_verified.dataset`); a bad file is one line,
  exit 2, nothing written. ``check`` adds how many instances have their harness image here. Not
  part of ``all``: name it.
* ALFWorld 2.1.2: ``json_2.1.2_tw-pddl.zip`` (the ``TW_PDDL_FILES_URL`` of alfworld 0.4.2's
  ``alfworld-download``).

ALFWorld's own downloader is not called: in alfworld 0.4.2 it is a console script
(``bin/alfworld-download``), not an importable function; its URLs are module constants with no
mirror or base-URL option; its ``download()`` uses ``requests`` (no ``file://``); importing it
creates ``$ALFWORLD_DATA`` or ``~/.cache/alfworld``; its ``main()`` also downloads the 170 MB
MaskRCNN detector and fetches the 2.1.2 game files, not 2.1.1. So ``fetch`` downloads the same
archives itself (default URLs above, checked against the installed script's constants by the
tests) and keeps only the files it verifies.

Robotouille's 200 benchmark instances (``instances/``) and the two demonstration instances
(``instances_train/``) are not in the upstream repository: the real engine makes them at load
time with its seeded generator (``randomize_environment(env_json, seed)``, retried with
seed+1, ... on failure: 38 of the 200 use another seed). ``fetch`` *generates* them, after the
download, from the fetched problem files and domain with
:mod:`workers.envs.robotouille.generator` (our re-implementation of that generator: same ``random`` draws in the same order; it reproduces the
recorded ``generated_environment_json`` and ``used_seed`` of all 200 + 2 instances, see
``bench/robotouille_generator.py``), plus the first observation and goal-set count from our
engine. The recorded files also hold the real engine's build times, which no machine can
reproduce, so a generated file cannot have the recorded file's sha256: the repository pins both
digests, ``robotouille.sha256`` (the recorded files, e.g. copied from a complete data folder) and
``robotouille-generated.sha256`` (the bytes ``fetch`` writes), and ``check`` accepts a file of
those two groups when it matches either one (its line says how many were generated).
``trajectories/`` (recorded on the real engine; read only by ``recap env replay`` and the tests)
are optional: their absence is noted, not a failure.

Exit status: 0 - every benchmark asked about has a folder and it verifies (``fetch``: every
benchmark was fetched and verified, or was already there and verifies); 1 - a check failed: a
benchmark has no folder, a file is missing or does not match, a download or an archive failed
(one line on stderr per failure); 2 - bad usage: unknown benchmark or option, ``--data-dir``
without a benchmark, a mirror folder that does not exist (one line on stderr); 130 -
interrupted (a fetch in progress leaves nothing behind).
"""

from __future__ import annotations

import argparse
import sys
from functools import partial
from typing import TextIO

from pipeline.cli.common import EXIT_USAGE, CommandParser, HelpExit, UsageError
from pipeline.data import DataError, InputError, MirrorError, check_folder, describe, folders, not_found, search
from pipeline.data_fetch import check_mirror, default_dest, fetch_one
from pipeline.errors import one_line
from recap.env import DataNotFoundError, EnvError, UnknownInstanceError
from workers.envs.data_sources import DataFolder
from workers.envs.swe_verified.get_images import DEFAULT_WORKERS, ImagesError, get_images, selected_records
from workers.envs.swe_verified.get_images import FOLDERS as IMAGE_FOLDERS
from workers.sandbox.base import SandboxError

EXIT_OK = 0
EXIT_FAILED = 1


def cmd_list(benches: list[DataFolder], data_dir: str | None, out: TextIO, optional: frozenset[str] = frozenset()) -> list[str]:
    """``recap data list``: print every place each benchmark's folder is looked for, marking the one
    used. Returns one failure line per benchmark without a folder (empty: all found), except for the
    ``optional`` ones (``list all`` shows the folders asked for by name too, whose absence fails
    nothing: ``swebench-verified``, the release's prompts)."""
    failures = []
    for bench in benches:
        rungs, used = search(bench, data_dir)
        if used is not None:
            print(f"{bench.name}: {describe(used)}", file=out)
        elif bench.name in optional:
            print(f"{bench.name}: not found (needed only by the sweeps that use it: recap data fetch {bench.name})", file=out)
        else:
            failures.append(f"{bench.name}: {not_found(bench, rungs)}")
            print(f"{bench.name}: not found", file=out)
        width = max(len(r.step) for r in rungs)
        for i, r in enumerate(rungs, 1):
            where = f"{r.path}: {r.status}" if r.path is not None else r.status
            mark = "  <- used" if r is used else ""
            print(f"  {i}. {r.step:<{width}}  {where}{mark}", file=out)
    return failures


def cmd_check(benches: list[DataFolder], data_dir: str | None, out: TextIO) -> list[str]:
    """``recap data check``: verify the folder each benchmark uses against its manifest, one printed
    line each. Returns one failure line per benchmark that is not found, cannot be read or is not
    intact (empty: all verified)."""
    failures = []
    for bench in benches:
        rungs, used = search(bench, data_dir)
        if used is None or used.path is None:
            reason = not_found(bench, rungs)
            print(f"{bench.name}: {reason}: FAILED", file=out)
            failures.append(f"{bench.name}: {reason}")
            continue
        try:
            result = check_folder(bench, used.path.resolve())
        except OSError as exc:
            print(f"{bench.name}: {used.path} ({used.step}): cannot read: {exc}: FAILED", file=out)
            failures.append(f"{bench.name}: cannot read {used.path}: {exc.strerror or exc}")
            continue
        result.source = used.step
        print(result.line(), file=out)
        if result.ok and bench.check_notes is not None:
            try:
                notes = bench.check_notes(used.path.resolve())
            except Exception as exc:  # a verified folder whose notes cannot be read: one failure line
                notes = []
                failures.append(f"{bench.name}: {one_line(exc)}")
            for note in notes:
                print(f"{bench.name}: {note}", file=out)
        if not result.ok:
            failures.append(f"{bench.name}: {sum(result.missing.values())} missing, {len(result.mismatched)} mismatched")
    return failures


def cmd_fetch(
    benches: list[DataFolder],
    dest: str | None,
    mirror: str | None,
    out: TextIO,
    from_file: str | None = None,
    subset: bool = False,
) -> list[str]:
    """``recap data fetch``: fetch, verify and move each benchmark's folder into place. Returns one
    failure line per benchmark that failed (nothing of it is written); a bad mirror, or ``--from``/
    ``--subset`` for a folder that is not loaded from a file, raises (exit 2) before any fetch, and
    so does a ``--from`` file that is not the folder's data (InputError)."""
    check_mirror(mirror)
    loaded = [b.name for b in benches if b.load is not None]
    if (from_file is not None or subset) and (len(benches) != 1 or not loaded):
        flag = "--from" if from_file is not None else "--subset"
        raise UsageError(
            f"{flag} is for a folder loaded from a file ({', '.join(n for n in folders() if folders()[n].load)}): name it as BENCH"
        )
    if mirror is not None and loaded and len(benches) == 1:
        raise UsageError(f"--mirror does not apply to {loaded[0]}: pass a local copy with --from FILE")
    failures = []
    for bench in benches:
        target = default_dest(bench, dest, several=len(benches) > 1)
        try:
            fetch_one(bench, target, mirror, out, from_file, subset)
        except DataError as exc:
            failures.append(f"{bench.name}: {exc}; nothing was written")
        except OSError as exc:  # the destination cannot be written (permissions, disk full)
            failures.append(f"{bench.name}: cannot write {target}: {exc.strerror or exc}; nothing was written")
    return failures


def _parser(out: TextIO) -> CommandParser:
    p = CommandParser(
        prog="recap data",
        description="Find, verify and fetch the benchmark data folders.",
        out=out,
        hint=True,
        epilog="examples:\n  recap data list\n  recap data check alfworld\n"
        "  recap data fetch robotouille --mirror /mnt/mirror\n\n"
        "exit status: 0 all verified; 1 a check or fetch failed; 2 bad usage",
    )
    sub = p.add_subparsers(
        dest="action",
        required=True,
        metavar="ACTION",
        help="list, check, fetch or images",
        parser_class=partial(CommandParser, out=out, hint=True),
    )  # type: ignore[call-overload]  # a class with its out bound
    choices = (*folders(), "all")
    for name, text in (
        ("list", "where each benchmark's folder is looked for, and which one is used"),
        ("check", "verify each folder against the sha256 manifest"),
    ):
        sp = sub.add_parser(
            name,
            help=text,
            description=text,
            epilog=f"examples:\n  recap data {name}\n  recap data {name} robotouille --data-dir ~/data/robotouille",
        )
        sp.add_argument(
            "bench", nargs="?", default="all", choices=choices, metavar="BENCH", help=f"one of {', '.join(choices)} (default all)"
        )
        sp.add_argument("--data-dir", dest="data_dir", metavar="DIR", help="look here first (needs BENCH)")
    f = sub.add_parser(
        "fetch",
        help="download, verify and install the data",
        description="Download what can be downloaded, verify it, then move it into place.",
        epilog="examples:\n  recap data fetch alfworld\n  recap data fetch all --mirror file:///mnt/mirror --dest ~/data",
    )
    f.add_argument(
        "bench", nargs="?", default="all", choices=choices, metavar="BENCH", help=f"one of {', '.join(choices)} (default all)"
    )
    f.add_argument(
        "--mirror", metavar="DIR_OR_URL", help="folder or URL prefix holding the upstream file names (default: upstream URLs)"
    )
    f.add_argument(
        "--from",
        dest="from_file",
        metavar="FILE",
        help="swebench-verified: a local copy of the dataset (Parquet or JSONL) instead of the Hugging Face Hub",
    )
    f.add_argument(
        "--subset",
        action="store_true",
        help="swebench-verified: accept fewer records than the full split, recorded as a subset",
    )
    f.add_argument(
        "--dest",
        metavar="DIR",
        help="the folder (with BENCH) or the parent of the folders (without); default ~/.cache/recap-eval/data/<bench>",
    )
    _add_images(sub)
    return p


def _add_images(sub: argparse._SubParsersAction[CommandParser]) -> None:
    """``recap data images``: the per-instance images a folder's instances run in."""
    im = sub.add_parser(
        "images",
        help="list, pull or build the per-instance images (swebench-verified)",
        description="List the SWE-bench harness's per-instance images the selected instances lack;\n"
        "pull them from Docker Hub (--pull) or build them with the harness (--build).",
        epilog="examples:\n  recap data images swebench-verified\n  recap data images swebench-verified django/django --pull "
        "--workers 8\n  recap data images swebench-verified django__django-11099 --build --dry-run\n\n"
        "exit status: 0 every selected instance has its image (at the end); 1 some are missing or failed; 2 bad usage",
    )
    im.add_argument("bench", choices=IMAGE_FOLDERS, metavar="BENCH", help=f"one of {', '.join(IMAGE_FOLDERS)}")
    im.add_argument(
        "selectors",
        nargs="*",
        default=[],
        metavar="SELECTOR",
        help="as `recap env list swe-verified` takes them: all, a repository (owner/name), an instance id (default all)",
    )
    how = im.add_mutually_exclusive_group()
    how.add_argument("--pull", action="store_true", help="pull the missing published images from Docker Hub")
    how.add_argument("--build", action="store_true", help="build the missing images with the SWE-bench harness")
    im.add_argument(
        "--workers",
        type=_workers,
        default=DEFAULT_WORKERS,
        metavar="N",
        help=f"pulls or builds at a time (default {DEFAULT_WORKERS})",
    )
    im.add_argument("--dry-run", dest="dry_run", action="store_true", help="print what --pull or --build would do")
    im.add_argument("--data-dir", dest="data_dir", metavar="DIR", help="the data folder (default: the usual search)")


def _workers(text: str) -> int:
    """argparse type: a whole number >= 1."""
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid whole number: {text!r}") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {text!r}")
    return n


def cmd_images(args: argparse.Namespace, out: TextIO) -> list[str]:
    """``recap data images``: list, pull or build the images the selected instances lack. Returns
    the failure lines; a bad selector is a UsageError, no data folder or no daemon a DataError."""
    if args.dry_run and not (args.pull or args.build):
        raise UsageError("--dry-run needs --pull or --build")
    try:
        recs = selected_records(args.selectors, args.data_dir)
    except UnknownInstanceError as exc:
        raise UsageError(str(exc)) from None
    except (DataNotFoundError, EnvError) as exc:
        raise DataError(str(exc)) from None
    action = "pull" if args.pull else "build" if args.build else None
    try:
        return get_images(args.bench, recs, action, args.workers, out, args.dry_run)
    except (ImagesError, SandboxError) as exc:
        raise DataError(str(exc)) from None


def parser() -> argparse.ArgumentParser:
    """The ``recap data`` parser (its ``--help`` to stdout)."""
    return _parser(sys.stdout)


def _run(args: argparse.Namespace, stdout: TextIO) -> list[str]:
    """The parsed action's failure lines (empty: all verified)."""
    if args.action == "images":
        return cmd_images(args, stdout)
    by_name = folders()
    benches = [b for b in by_name.values() if b.in_all] if args.bench == "all" else [by_name[args.bench]]
    if getattr(args, "data_dir", None) is not None and args.bench == "all":
        raise UsageError("--data-dir names one benchmark's folder: give BENCH too")
    if args.action == "list":  # every folder, the ones asked for by name too (their absence fails nothing)
        if args.bench != "all":
            return cmd_list(benches, args.data_dir, stdout)
        optional = frozenset(n for n, b in by_name.items() if not b.in_all)
        return cmd_list(list(by_name.values()), args.data_dir, stdout, optional)
    if args.action == "check":
        return cmd_check(benches, args.data_dir, stdout)
    return cmd_fetch(benches, args.dest, args.mirror, stdout, args.from_file, args.subset)


def data_main(argv: list[str], stdout: TextIO, stderr: TextIO) -> int:
    """``recap data ...``: returns the exit status (0 ok, 1 check/fetch failed, 2 bad usage)."""
    try:
        args = _parser(stdout).parse_args(argv)
        failures = _run(args, stdout)
    except HelpExit as exc:
        return exc.status
    except (UsageError, MirrorError, InputError) as exc:
        print(f"recap: error: data: {one_line(exc)}", file=stderr)
        return EXIT_USAGE
    except DataError as exc:
        print(f"recap: error: data: {one_line(exc)}", file=stderr)
        return EXIT_FAILED
    except KeyboardInterrupt:  # fetch has removed its stage already (finally)
        print("recap: interrupted", file=stderr)
        return 130
    stdout.flush()
    for failure in failures:
        print(f"recap: error: data {args.action}: {one_line(failure)}", file=stderr)
    return EXIT_FAILED if failures else EXIT_OK


def main(argv: list[str]) -> int:
    """``recap data ...`` on the process's stdout and stderr."""
    return data_main(argv, sys.stdout, sys.stderr)
