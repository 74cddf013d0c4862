"""Where each benchmark's data folder is and whether it is intact: the sha256 manifests and the check.

The data never lives in this repository; this repository carries each folder's manifest
(``pipeline/manifests/<bench>.sha256``, ``sha256sum`` format: metadata, not data). The folders,
their file groups and sources are declared by the benchmarks (``Benchmark.data_folders``); the
search order is :mod:`workers.envs.data_paths`'s. ``recap data`` (:mod:`pipeline.cli.data`) is the
command line over this module and :mod:`pipeline.data_fetch`.
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from recap.plural import count
from workers.envs import data_paths
from workers.envs.data_sources import DataFolder, Group
from workers.envs.registry import data_folders

MANIFEST_DIR = Path(__file__).resolve().parent / "manifests"
MANIFEST_NAME = "MANIFEST.sha256"

_CHUNK = 1 << 20


class DataError(Exception):
    """A check or a fetch failed: ``recap data`` exits 1."""


class MirrorError(Exception):
    """A ``--mirror`` that cannot work, refused before any download: ``recap data`` exits 2."""


class InputError(Exception):
    """``--from FILE`` is not the folder's data (bad records, wrong count): ``recap data`` exits 2, nothing written."""


# ---------------------------------------------------------------------------------------------
# what each benchmark folder holds: declared by the benchmarks (Benchmark.data_folders)


def folders() -> dict[str, DataFolder]:
    """Every data folder the registered benchmarks declare, by name (``robotouille``,
    ``alfworld``, ``alfworld-2.1.2``), in registration order."""
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


def describe(rung: data_paths.Rung) -> str:
    """A search rung as ``path (step)``."""
    return f"{rung.path} ({rung.step})"


def not_found(bench: DataFolder, rungs: list[data_paths.Rung]) -> str:
    """Why no folder of ``bench`` is used: the explicit folder that is not one, or how to get one."""
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
        head = f"{self.bench.name}: {where}: {count(self.checked, 'file')} checked: "
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
    """``folder`` against the repository's manifest of ``bench`` (files of groups ``only`` keeps);
    a folder the benchmark loads itself (``bench.load``) against its own ``MANIFEST.sha256``."""
    if bench.load is not None:
        own = folder / MANIFEST_NAME
        if not own.is_file():
            return CheckResult(bench, folder, checked=1, missing={MANIFEST_NAME: 1})
        manifest = read_manifest(own)
    else:
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
