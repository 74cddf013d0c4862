"""``recap data fetch``'s work: download, verify, generate, then move a benchmark's data folder into place.

Each file is checked against the repository's manifest (:mod:`pipeline.data`) before the folder
is moved into place: it is staged in a hidden folder next to the destination and renamed at the
end; a failure removes the stage, so no half-written folder is ever left. Sources and why
ALFWorld's own downloader is not called: :mod:`pipeline.cli.data`.
"""

from __future__ import annotations

import hashlib
import os
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
from functools import partial
from pathlib import Path
from typing import IO, TextIO

from pipeline.data import (
    MANIFEST_NAME,
    DataError,
    InputError,
    MirrorError,
    check_folder,
    describe,
    generated_manifest_file,
    manifest_file,
    read_manifest,
    search,
    sha256_file,
    write_manifest,
)
from pipeline.errors import one_line
from recap.plural import count
from workers.envs import data_paths
from workers.envs.data_sources import DataFolder, Source, is_url

_CHUNK = 1 << 20
_TIMEOUT_S = 60
_GIT_TIMEOUT_S = 600
#: no data file is near this size; a larger member is refused before it fills the disk
_MAX_FILE_BYTES = 256 << 20


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
    does not exist, or a URL that is not file://, http:// or https:// (MirrorError). None: no mirror,
    nothing to check."""
    if mirror is None:
        return
    local = _local_path(mirror)
    if local is not None and not local.is_dir():
        raise MirrorError(f"mirror folder {mirror} does not exist")
    if local is None and urllib.parse.urlparse(mirror).scheme not in ("http", "https"):
        raise MirrorError(f"mirror {mirror!r}: use a folder, a file:// URL or an http(s):// URL")


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
        f"read {count(len(paths), 'file')} at {source.ref[:12]} from {location}",
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
        raise DataError(f"the generator wrote {count(len(written), 'file')}, expected {len(expected)}")
    got = {}
    for rel in sorted(expected):
        got[rel] = sha256_file(data / rel)
        if got[rel] != pinned[rel]:
            raise DataError(
                f"{rel} as generated here does not match {generated_manifest_file(bench).name} (sha256 "
                f"{got[rel][:12]}..., expected {pinned[rel][:12]}...): the problem files, the generator or the engine changed"
            )
    return got


def _stage_loaded(bench: DataFolder, from_file: str | None, subset: bool, stage: Path, out: TextIO) -> dict[str, str]:
    """A folder the benchmark loads itself (``bench.load``): its files in ``stage/data`` with their
    own manifest. InputError (exit 2) for bad input, DataError when nothing can be read."""
    assert bench.load is not None
    data = stage / "data"
    data.mkdir()
    try:
        written = bench.load(from_file, subset, data, out)
    except ValueError as exc:
        raise InputError(f"{bench.name}: {one_line(exc)}; nothing was written") from None
    except Exception as exc:  # the loader's library failing (no network, no package): one line
        raise DataError(one_line(exc) or type(exc).__name__) from None
    got = {rel: sha256_file(data / rel) for rel in written}
    write_manifest(data / MANIFEST_NAME, got)
    return got


def _same_as(dest: Path, got: dict[str, str]) -> bool:
    """Whether the folder ``dest`` already holds exactly the files ``got`` (by sha256)."""
    return all((dest / rel).is_file() and sha256_file(dest / rel) == digest for rel, digest in got.items())


def fetch_one(
    bench: DataFolder, dest: Path, mirror: str | None, out: TextIO, from_file: str | None = None, subset: bool = False
) -> None:
    """Fetch ``bench`` into ``dest`` (must not exist, or be empty); DataError on any failure,
    leaving ``dest`` and its parents as they were. A folder the benchmark loads itself
    (``bench.load``: ``from_file``, ``subset``) is read and checked before ``dest`` is looked at,
    so bad input is refused (InputError) even where a folder exists."""
    dest = dest.expanduser().absolute()
    if bench.load is not None:
        _fetch_loaded(bench, dest, from_file, subset, out)
        return
    if dest.exists() and (not dest.is_dir() or any(dest.iterdir())):
        if not dest.is_dir():
            raise DataError(f"{dest} exists and is not a folder")
        result = check_folder(bench, dest, only=lambda g: g.fetchable)
        if result.ok:
            print(f"{bench.name}: {dest} is already there and verifies ({count(result.checked, 'file')})", file=out)
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
    print(f"{bench.name}: {dest}: {count(len(got), 'file')} fetched and verified", file=out)
    if bench.after_fetch:
        print(f"{bench.name}: note: {bench.after_fetch}", file=out)
    _note_precedence(bench, dest, out)


def _fetch_loaded(bench: DataFolder, dest: Path, from_file: str | None, subset: bool, out: TextIO) -> None:
    """:func:`fetch_one` for a folder the benchmark loads itself: stage, check, then move into place."""
    with tempfile.TemporaryDirectory(prefix=f".{bench.name}.load-") as tmp:
        print(f"{bench.name}: loading {from_file or 'from upstream'}", file=out, flush=True)
        got = _stage_loaded(bench, from_file, subset, Path(tmp), out)
        if dest.exists() and (not dest.is_dir() or any(dest.iterdir())):
            if dest.is_dir() and _same_as(dest, got):
                print(f"{bench.name}: {dest} is already there and holds the same records ({count(len(got), 'file')})", file=out)
                return
            raise DataError(f"{dest} exists and holds other files; remove it or pass another --dest")
        created = [p for p in [dest.parent, *dest.parent.parents] if not p.exists()]
        done = False
        try:
            dest.parent.mkdir(parents=True, exist_ok=True)
            stage = Path(tempfile.mkdtemp(prefix=f".{dest.name}.partial-", dir=dest.parent))
            try:
                shutil.copytree(Path(tmp) / "data", stage / "data")
                if dest.is_dir():
                    dest.rmdir()  # empty (checked above)
                os.rename(stage / "data", dest)
                done = True
            finally:
                shutil.rmtree(stage, ignore_errors=True)
        finally:
            if not done:
                for folder in created:
                    try:
                        folder.rmdir()
                    except OSError:
                        break
    print(f"{bench.name}: {dest}: {count(len(got), 'file')} stored and verified", file=out)
    if bench.after_fetch:
        print(f"{bench.name}: note: {bench.after_fetch}", file=out)
    _note_precedence(bench, dest, out)


def _note_precedence(bench: DataFolder, dest: Path, out: TextIO) -> None:
    """Say so when the resolver will not pick the folder just fetched."""
    _rungs, used = search(bench, None)
    if used is not None and used.path is not None and used.path.resolve() == dest.resolve():
        return
    env_var = bench.location.env_var
    where = f"{describe(used)} is used instead" if used is not None else "it is not on the search path"
    print(f"{bench.name}: note: {where}; set {env_var}={dest} to use this folder", file=out)


def default_dest(bench: DataFolder, dest: str | None, several: bool) -> Path:
    """Where ``fetch`` puts ``bench``: recap-eval's cache without ``--dest``; else ``--dest``
    itself, or ``--dest/<bench>`` when several benchmarks are fetched at once."""
    if dest is None:
        return data_paths.recap_cache_root() / bench.name
    root = Path(dest).expanduser()
    return root / bench.name if several else root
