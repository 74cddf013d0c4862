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
import hashlib
import os
import re
import shutil
import subprocess
import tarfile
import tempfile
import urllib.error
import urllib.parse
import urllib.request
import zipfile
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import IO, Any, NoReturn, TextIO

from pipeline.errors import one_line
from workers.envs import data_paths
from workers.envs.data_sources import DataFolder, Group, Source, is_url

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2

MANIFEST_DIR = Path(__file__).resolve().parent / "manifests"
MANIFEST_NAME = "MANIFEST.sha256"

_CHUNK = 1 << 20
_TIMEOUT_S = 60
_GIT_TIMEOUT_S = 600
#: no data file is near this size; a larger member is refused before it fills the disk
_MAX_FILE_BYTES = 256 << 20


class UsageError(Exception):
    """Bad command line: exit 2."""


class DataError(Exception):
    """A check or a fetch failed: exit 1."""


# ---------------------------------------------------------------------------------------------
# what each benchmark folder holds: declared by the benchmarks (Benchmark.data_folders)


def folders() -> dict[str, DataFolder]:
    """Every data folder the registered benchmarks declare, by name (``robotouille``,
    ``alfworld``, ``alfworld-2.1.2``), in registration order."""
    from workers.envs.registry import data_folders

    return data_folders()


def manifest_file(bench: DataFolder) -> Path:
    """The sha256 manifest this repository carries for ``bench``
    (``pipeline/manifests/<bench>.sha256``): the recorded files its folder must hold."""
    return MANIFEST_DIR / f"{bench.name}.sha256"


def generated_manifest_file(bench: DataFolder) -> Path:
    """sha256 of the files ``generate`` writes (they differ from the recorded ones)."""
    return MANIFEST_DIR / f"{bench.name}-generated.sha256"


def read_manifest(path: Path) -> dict[str, str]:
    """``{relative path: sha256}`` from a ``sha256sum``-format file (``<hex>  ./path``)."""
    entries: dict[str, str] = {}
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if not line.strip():
            continue
        digest, sep, name = line.partition(" ")
        name = name.lstrip(" *")
        if not sep or not re.fullmatch(r"[0-9a-f]{64}", digest) or not name:
            raise DataError(f"malformed manifest line {number} in {path}")
        entries[name.removeprefix("./")] = digest
    return entries


def write_manifest(path: Path, entries: dict[str, str]) -> None:
    """Write ``entries`` (``{relative path: sha256}``) in ``sha256sum`` format, sorted by path, so
    :func:`read_manifest` and ``sha256sum -c`` can read it back."""
    path.write_text("".join(f"{entries[rel]}  ./{rel}\n" for rel in sorted(entries)), encoding="utf-8")


def sha256_file(path: Path) -> str:
    """The hex sha256 of a file's contents, read in chunks so a large file never sits in memory whole."""
    digest = hashlib.sha256()
    with path.open("rb") as f:
        for chunk in iter(lambda: f.read(_CHUNK), b""):
            digest.update(chunk)
    return digest.hexdigest()


# ---------------------------------------------------------------------------------------------
# where (list)


def search(bench: DataFolder, data_dir: str | None) -> tuple[list[data_paths.Rung], data_paths.Rung | None]:
    """Every rung of the search for ``bench`` and the one whose folder is used (None: none)."""
    if bench.search is not None:
        return bench.search(data_dir)
    rungs = data_paths.search(bench.location, data_dir, stop_at_first=False)
    return rungs, data_paths.chosen(rungs)


def _describe(rung: data_paths.Rung) -> str:
    return f"{rung.path} ({rung.step})"


def cmd_list(benches: list[DataFolder], data_dir: str | None, out: TextIO) -> list[str]:
    """``recap data list``: print every place each benchmark's folder is looked for, marking the one
    used. Returns one failure line per benchmark without a folder (empty: all found)."""
    failures = []
    for bench in benches:
        rungs, used = search(bench, data_dir)
        if used is not None:
            print(f"{bench.name}: {_describe(used)}", file=out)
        else:
            failures.append(f"{bench.name}: {_not_found(bench, rungs)}")
            print(f"{bench.name}: not found", file=out)
        width = max(len(r.step) for r in rungs)
        for i, r in enumerate(rungs, 1):
            where = f"{r.path}: {r.status}" if r.path is not None else r.status
            mark = "  <- used" if r is used else ""
            print(f"  {i}. {r.step:<{width}}  {where}{mark}", file=out)
    return failures


def _not_found(bench: DataFolder, rungs: list[data_paths.Rung]) -> str:
    bad = data_paths.first_explicit_error(rungs)
    if bad is not None:
        return f"{bad.path} (from {bad.step}) is not a {bench.title} folder: {bad.status.removeprefix('invalid: ')}"
    return f"no folder found; run `recap data fetch {bench.name}` (see `recap data list {bench.name}`)"


# ---------------------------------------------------------------------------------------------
# check


@dataclass
class CheckResult:
    """What :func:`check_folder` found in one folder: files checked, missing ones counted by group
    prefix (required and optional apart) and mismatched ones. ``ok`` ignores optional files;
    ``line`` is the report line of ``recap data check``."""

    bench: DataFolder
    folder: Path
    source: str = ""  # the rung it was found on ("checkout", "$ROBOTOUILLE_DATA", ...)
    checked: int = 0
    missing: dict[str, int] = field(default_factory=dict)  # group prefix -> count (required)
    optional_missing: dict[str, int] = field(default_factory=dict)
    mismatched: list[str] = field(default_factory=list)
    generated: int = 0  # files that match the digest of a generated file, not the recorded one

    @property
    def ok(self) -> bool:
        return not self.missing and not self.mismatched

    def line(self) -> str:
        where = f"{self.folder} ({self.source})" if self.source else str(self.folder)
        head = f"{self.bench.name}: {where}: {self.checked} files checked: "
        n_missing = sum(self.missing.values())
        optional = ""
        if self.optional_missing:
            groups = ", ".join(f"{g} ({n})" for g, n in self.optional_missing.items())
            notes = "; ".join(dict.fromkeys(self.bench.group_of(g).note for g in self.optional_missing))
            optional = f" ({sum(self.optional_missing.values())} optional files absent: {groups}: {notes})"
        if self.generated:
            optional = f" ({self.generated} of them generated by recap-eval)" + optional
        if self.ok:
            return head + "OK" + optional
        parts = [f"{n_missing} missing", f"{len(self.mismatched)} mismatched"]
        text = head + ", ".join(parts)
        if self.mismatched:
            text += f" (e.g. {self.mismatched[0]})"
        if self.missing:
            where = ", ".join(f"{g} ({n})" for g, n in self.missing.items())
            text += f": missing {where}"
            unfetchable = [g for g in self.missing if not self.bench.group_of(g).fetchable]
            if unfetchable:
                text += " - " + "; ".join(dict.fromkeys(self.bench.group_of(g).note for g in unfetchable))
            if len(unfetchable) < len(self.missing):
                text += f"; `recap data fetch {self.bench.name}` gets the rest"
        elif self.mismatched:
            text += f"; fetch a fresh copy: `recap data fetch {self.bench.name} --dest NEW_FOLDER`"
        return text + optional + ": FAILED"


def check_folder(bench: DataFolder, folder: Path, only: Callable[[Group], bool] = lambda g: True) -> CheckResult:
    """``folder`` against the repository's manifest of ``bench`` (files of groups ``only`` keeps)."""
    manifest = read_manifest(manifest_file(bench))
    generated = read_manifest(generated_manifest_file(bench)) if bench.generate is not None else {}
    result = CheckResult(bench, folder)
    for rel, digest in manifest.items():
        group = bench.group_of(rel)
        if not only(group):
            continue
        result.checked += 1
        path = folder / rel
        if not path.is_file():
            bucket = result.missing if group.required else result.optional_missing
            bucket[group.prefix] = bucket.get(group.prefix, 0) + 1
            continue
        actual = sha256_file(path)
        if actual == digest:
            continue
        if group.generated and actual == generated.get(rel):
            result.generated += 1
        else:
            result.mismatched.append(rel)
    return result


def cmd_check(benches: list[DataFolder], data_dir: str | None, out: TextIO) -> list[str]:
    """``recap data check``: verify the folder each benchmark uses against its manifest, one printed
    line each. Returns one failure line per benchmark that is not found, cannot be read or is not
    intact (empty: all verified)."""
    failures = []
    for bench in benches:
        rungs, used = search(bench, data_dir)
        if used is None or used.path is None:
            reason = _not_found(bench, rungs)
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
        if not result.ok:
            failures.append(f"{bench.name}: {sum(result.missing.values())} missing, {len(result.mismatched)} mismatched")
    return failures


# ---------------------------------------------------------------------------------------------
# fetch


def _local_path(location: str) -> Path | None:
    """The local file a location names (a path or a file:// URL), None for a remote URL."""
    if not is_url(location):
        return Path(location)
    parsed = urllib.parse.urlparse(location)
    if parsed.scheme == "file":
        return Path(urllib.request.url2pathname(parsed.path))
    return None


def check_mirror(mirror: str | None) -> None:
    """Refuse a ``--mirror`` that cannot work before anything is downloaded: a local folder that
    does not exist, or a URL that is not file://, http:// or https:// (UsageError). None: no mirror,
    nothing to check."""
    if mirror is None:
        return
    local = _local_path(mirror)
    if local is not None and not local.is_dir():
        raise UsageError(f"mirror folder {mirror} does not exist")
    if local is None and urllib.parse.urlparse(mirror).scheme not in ("http", "https"):
        raise UsageError(f"mirror {mirror!r}: use a folder, a file:// URL or an http(s):// URL")


def _obtain(source: Source, mirror: str | None, downloads: Path, out: TextIO) -> tuple[Path, str]:
    """The source's file on this machine (downloaded into ``downloads`` if remote) and where it came from."""
    location = source.location(mirror)
    local = _local_path(location)
    if local is not None:
        if not local.is_file():
            raise DataError(f"{source.name} is not in the mirror ({local} does not exist)")
        return local, str(local)
    target = downloads / source.name
    print(f"  downloading {location}", file=out, flush=True)
    request = urllib.request.Request(location, headers={"User-Agent": "recap-eval data fetch"})
    try:
        with urllib.request.urlopen(request, timeout=_TIMEOUT_S) as response, target.open("wb") as f:
            shutil.copyfileobj(response, f, _CHUNK)
    except urllib.error.HTTPError as exc:
        raise DataError(f"cannot download {location}: HTTP {exc.code} {exc.reason}") from None
    except (urllib.error.URLError, OSError, TimeoutError) as exc:
        reason = getattr(exc, "reason", None) or exc
        raise DataError(f"cannot download {location}: {reason}") from None
    return target, location


def _git_dir(folder: Path) -> Path | None:
    """The git directory of a local repository folder (a work tree's ``.git``, or a bare one), else None."""
    if (folder / ".git").exists():
        return folder / ".git"
    if (folder / "HEAD").is_file() and (folder / "objects").is_dir():
        return folder
    return None


def _git(args: list[str], what: str) -> None:
    """Run git; a failure is a DataError naming ``what`` with git's last line."""
    try:
        done = subprocess.run(["git", *args], capture_output=True, text=True, timeout=_GIT_TIMEOUT_S)
    except FileNotFoundError:
        raise DataError(f"cannot {what}: git is not installed") from None
    except subprocess.TimeoutExpired:
        raise DataError(f"cannot {what}: git took over {_GIT_TIMEOUT_S} s") from None
    if done.returncode != 0:
        lines = [line for line in done.stderr.strip().splitlines() if line.strip()]
        raise DataError(f"cannot {what}: {lines[-1] if lines else f'git exited {done.returncode}'}")


def _git_archive(source: Source, mirror: str | None, paths: list[str], downloads: Path, out: TextIO) -> tuple[Path, str]:
    """The manifest's ``paths`` at the pinned commit ``source.ref``, as a tar.gz in ``downloads``.

    A local repository (``--mirror DIR``: a clone, bare or not) is read in place with ``git
    archive``; a URL (GitHub by default) is fetched first into a bare repository in ``downloads``:
    that one commit, without history, and only the blobs the archive reads (a partial clone), so
    the release's large data files are never downloaded."""
    location = source.location(mirror)
    target = downloads / f"{source.name}-{source.ref[:12]}.tar.gz"
    if is_url(location) and _local_path(location) is None:
        repo = downloads / f"{source.name}.git"
        print(f"  fetching {location} at {source.ref[:12]}", file=out, flush=True)
        _git(["init", "-q", "--bare", str(repo)], f"create {repo}")
        _git(
            ["-C", str(repo), "fetch", "-q", "--depth", "1", "--filter=blob:none", location, source.ref],
            f"fetch {source.ref[:12]} from {location}",
        )
        git_dir = repo
    else:
        folder = _local_path(location) or Path(location)
        found = _git_dir(folder)
        if found is None:
            raise DataError(f"{folder} is not a git repository (the mirror of {source.name} must be a clone of it)")
        git_dir = found
    _git(
        ["--git-dir", str(git_dir), "archive", "--format=tar.gz", "-o", str(target), source.ref, "--", *paths],
        f"read {len(paths)} files at {source.ref[:12]} from {location}",
    )
    return target, f"{location}@{source.ref[:12]}"


def _members(path: Path, kind: str, label: str) -> Iterator[tuple[str, Callable[[], IO[bytes]]]]:
    """(member name, opener) for every regular file of an archive; a broken archive is a DataError."""
    try:
        if kind == "zip":
            with zipfile.ZipFile(path) as archive:
                for info in archive.infolist():
                    if not info.is_dir():
                        yield info.filename, partial(archive.open, info)
        else:
            with tarfile.open(path, "r|gz") as archive:
                for member in archive:
                    if member.isfile():
                        yield member.name, partial(_tar_member, archive, member)
    except (zipfile.BadZipFile, tarfile.TarError, zlib.error, EOFError, OSError, ValueError) as exc:
        raise DataError(f"{label} is not a readable {kind} archive ({one_line(exc) or type(exc).__name__})") from None


def _tar_member(archive: tarfile.TarFile, member: tarfile.TarInfo) -> IO[bytes]:
    f = archive.extractfile(member)
    if f is None:
        raise tarfile.TarError(f"cannot read {member.name}")
    return f


def _binary_opener(path: Path) -> Callable[[], IO[bytes]]:
    """Opens ``path`` for reading bytes, when called."""
    return lambda: path.open("rb")


def _save(opener: Callable[[], IO[bytes]], target: Path) -> str:
    """Copy a stream to ``target`` and return its sha256."""
    target.parent.mkdir(parents=True, exist_ok=True)
    digest = hashlib.sha256()
    size = 0
    with opener() as src, target.open("wb") as dst:
        for chunk in iter(lambda: src.read(_CHUNK), b""):
            size += len(chunk)
            if size > _MAX_FILE_BYTES:
                raise DataError(f"{target.name} is larger than {_MAX_FILE_BYTES >> 20} MiB: not the expected file")
            digest.update(chunk)
            dst.write(chunk)
    return digest.hexdigest()


def _stage(bench: DataFolder, mirror: str | None, stage: Path, out: TextIO) -> dict[str, str]:
    """Fetch every fetchable manifest file of ``bench`` into ``stage/data``; verify each one.
    Returns the files written with their sha256."""
    manifest = read_manifest(manifest_file(bench))
    wanted = {rel: d for rel, d in manifest.items() if bench.group_of(rel).fetchable and not bench.group_of(rel).generated}
    data, downloads = stage / "data", stage / "downloads"
    data.mkdir()
    downloads.mkdir()
    got: dict[str, str] = {}
    origin: dict[str, str] = {}
    for source in bench.sources:
        if source.kind == "git":
            path, where = _git_archive(source, mirror, sorted(wanted), downloads, out)
        else:
            path, where = _obtain(source, mirror, downloads, out)
        if source.kind == "file":
            if source.saves_as in wanted:
                got[source.saves_as] = _save(_binary_opener(path), data / source.saves_as)
                origin[source.saves_as] = where
        else:
            try:
                for member, opener in _members(path, "tar.gz" if source.kind == "git" else source.kind, source.name):
                    rel = bench.member_path(member)
                    if rel in wanted and rel not in got:
                        got[rel] = _save(opener, data / rel)
                        origin[rel] = where
            except (zlib.error, EOFError, OSError, zipfile.BadZipFile, tarfile.TarError) as exc:
                raise DataError(f"{source.name} is not a readable {source.kind} archive ({one_line(exc)})") from None
        if path.parent == downloads:
            path.unlink()  # keep the stage small: archives are large, their files are extracted
    absent = sorted(set(wanted) - set(got))
    if absent:
        raise DataError(
            f"the sources lack {len(absent)} of the {len(wanted)} files needed (e.g. {absent[0]}); "
            "wrong mirror or upstream changed"
        )
    for rel in sorted(got):
        if got[rel] != wanted[rel]:
            raise DataError(
                f"{rel} from {origin[rel]} does not match the manifest (sha256 {got[rel][:12]}..., "
                f"expected {wanted[rel][:12]}...): corrupted download or wrong mirror"
            )
    if bench.generate is not None:
        got.update(_generate(bench, bench.generate, data, out))
    write_manifest(data / MANIFEST_NAME, got)
    return got


def _generate(bench: DataFolder, generate: Callable[[Path], list[str]], data: Path, out: TextIO) -> dict[str, str]:
    """Run ``bench.generate`` on the verified download; every file it must write is checked
    against the pinned digests of generated files. Returns the files with their sha256."""
    pinned = read_manifest(generated_manifest_file(bench))
    expected = {rel for rel in read_manifest(manifest_file(bench)) if bench.group_of(rel).generated}
    if set(pinned) != expected:
        raise DataError(f"{generated_manifest_file(bench).name} does not list the files of the generated groups")
    print(f"  generating {', '.join(g.prefix for g in bench.groups if g.generated)}", file=out, flush=True)
    try:
        written = set(generate(data))
    except Exception as exc:  # any failure of the generator is a failed fetch with one line, not a traceback
        raise DataError(f"cannot generate the {bench.title} instances: {one_line(exc) or type(exc).__name__}") from None
    if written != expected:
        raise DataError(f"the generator wrote {len(written)} files, expected {len(expected)}")
    got = {}
    for rel in sorted(expected):
        got[rel] = sha256_file(data / rel)
        if got[rel] != pinned[rel]:
            raise DataError(
                f"{rel} as generated here does not match {generated_manifest_file(bench).name} (sha256 "
                f"{got[rel][:12]}..., expected {pinned[rel][:12]}...): the problem files, the generator or the engine changed"
            )
    return got


def fetch_one(bench: DataFolder, dest: Path, mirror: str | None, out: TextIO) -> None:
    """Fetch ``bench`` into ``dest`` (must not exist, or be empty); DataError on any failure,
    leaving ``dest`` and its parents as they were."""
    dest = dest.expanduser().absolute()
    if dest.exists() and (not dest.is_dir() or any(dest.iterdir())):
        if not dest.is_dir():
            raise DataError(f"{dest} exists and is not a folder")
        result = check_folder(bench, dest, only=lambda g: g.fetchable)
        if result.ok:
            print(f"{bench.name}: {dest} is already there and verifies ({result.checked} files)", file=out)
            return
        raise DataError(
            f"{dest} exists and does not verify ({sum(result.missing.values())} missing, "
            f"{len(result.mismatched)} mismatched); remove it or pass another --dest"
        )
    created = [p for p in [dest.parent, *dest.parent.parents] if not p.exists()]
    stage: Path | None = None
    done = False
    try:
        dest.parent.mkdir(parents=True, exist_ok=True)
        stage = Path(tempfile.mkdtemp(prefix=f".{dest.name}.partial-", dir=dest.parent))
        print(f"{bench.name}: fetching into {dest}", file=out, flush=True)
        got = _stage(bench, mirror, stage, out)
        if dest.is_dir():
            dest.rmdir()  # empty (checked above)
        os.rename(stage / "data", dest)
        done = True
    finally:
        if stage is not None:
            shutil.rmtree(stage, ignore_errors=True)
        if not done:
            for folder in created:  # innermost first: parents this call created, if still empty
                try:
                    folder.rmdir()
                except OSError:
                    break
    print(f"{bench.name}: {dest}: {len(got)} files fetched and verified", file=out)
    if bench.after_fetch:
        print(f"{bench.name}: note: {bench.after_fetch}", file=out)
    _note_precedence(bench, dest, out)


def _note_precedence(bench: DataFolder, dest: Path, out: TextIO) -> None:
    """Say so when the resolver will not pick the folder just fetched."""
    _rungs, used = search(bench, None)
    if used is not None and used.path is not None and used.path.resolve() == dest.resolve():
        return
    env_var = bench.location.env_var
    where = f"{_describe(used)} is used instead" if used is not None else "it is not on the search path"
    print(f"{bench.name}: note: {where}; set {env_var}={dest} to use this folder", file=out)


def default_dest(bench: DataFolder, dest: str | None, several: bool) -> Path:
    """Where ``fetch`` puts ``bench``: recap-eval's cache without ``--dest``; else ``--dest``
    itself, or ``--dest/<bench>`` when several benchmarks are fetched at once."""
    if dest is None:
        return data_paths.recap_cache_root() / bench.name
    root = Path(dest).expanduser()
    return root / bench.name if several else root


def cmd_fetch(benches: list[DataFolder], dest: str | None, mirror: str | None, out: TextIO) -> list[str]:
    """``recap data fetch``: fetch, verify and move each benchmark's folder into place. Returns one
    failure line per benchmark that failed (nothing of it is written); a bad mirror raises
    UsageError before any fetch."""
    check_mirror(mirror)
    failures = []
    for bench in benches:
        target = default_dest(bench, dest, several=len(benches) > 1)
        try:
            fetch_one(bench, target, mirror, out)
        except DataError as exc:
            failures.append(f"{bench.name}: {exc}; nothing was written")
        except OSError as exc:  # the destination cannot be written (permissions, disk full)
            failures.append(f"{bench.name}: cannot write {target}: {exc.strerror or exc}; nothing was written")
    return failures


# ---------------------------------------------------------------------------------------------
# command line


class _Parser(argparse.ArgumentParser):
    """argparse that reports into the given streams and raises instead of exiting."""

    def __init__(self, *args: Any, out: TextIO, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.out = out

    def error(self, message: str) -> NoReturn:
        where = self.prog.removeprefix("recap").strip()
        raise UsageError(f"{message} (see recap {where} --help)")

    def exit(self, status: int = 0, message: str | None = None) -> NoReturn:
        if message:
            self.out.write(message)
        raise _Exit(status)

    def print_help(self, file: Any = None) -> None:
        self.out.write(self.format_help())

    def print_usage(self, file: Any = None) -> None:
        self.out.write(self.format_usage())


class _Exit(Exception):
    def __init__(self, status: int) -> None:
        super().__init__(status)
        self.status = status


def _parser(out: TextIO) -> _Parser:
    p = _Parser(
        prog="recap data",
        description="Find, verify and fetch the benchmark data folders.",
        out=out,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  recap data list\n  recap data check alfworld\n"
        "  recap data fetch robotouille --mirror /mnt/mirror\n\n"
        "exit status: 0 all verified; 1 a check or fetch failed; 2 bad usage",
    )
    sub = p.add_subparsers(
        dest="action", required=True, metavar="ACTION", help="list, check or fetch", parser_class=partial(_Parser, out=out)
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
            formatter_class=argparse.RawDescriptionHelpFormatter,
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
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  recap data fetch alfworld\n  recap data fetch all --mirror file:///mnt/mirror --dest ~/data",
    )
    f.add_argument(
        "bench", nargs="?", default="all", choices=choices, metavar="BENCH", help=f"one of {', '.join(choices)} (default all)"
    )
    f.add_argument(
        "--mirror", metavar="DIR_OR_URL", help="folder or URL prefix holding the upstream file names (default: upstream URLs)"
    )
    f.add_argument(
        "--dest",
        metavar="DIR",
        help="the folder (with BENCH) or the parent of the folders (without); default ~/.cache/recap-eval/data/<bench>",
    )
    return p


def data_main(argv: list[str], stdout: TextIO, stderr: TextIO) -> int:
    """``recap data ...``: returns the exit status (0 ok, 1 check/fetch failed, 2 bad usage)."""
    try:
        args = _parser(stdout).parse_args(argv)
        by_name = folders()
        benches = [b for b in by_name.values() if b.in_all] if args.bench == "all" else [by_name[args.bench]]
        if getattr(args, "data_dir", None) is not None and args.bench == "all":
            raise UsageError("--data-dir names one benchmark's folder: give BENCH too")
        if args.action == "list":
            failures = cmd_list(benches, args.data_dir, stdout)
        elif args.action == "check":
            failures = cmd_check(benches, args.data_dir, stdout)
        else:
            failures = cmd_fetch(benches, args.dest, args.mirror, stdout)
    except _Exit as exc:
        return exc.status
    except UsageError as exc:
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
