"""What a benchmark's data folder holds and where its files come from: the catalogue ``recap data`` reads.

Why here and not in ``pipeline/data.py``: the file groups, download URLs and archive layouts
are facts about one benchmark, so each benchmark package declares its folders as
:class:`DataFolder` values (through :meth:`workers.envs.registry.Benchmark.data_folders`), and
``recap data list/check/fetch`` works on whatever the registered benchmarks declare. The
sha256 manifests stay with the command (``pipeline/manifests/<folder>.sha256``).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

from workers.envs.data_paths import DataLocation, Rung


def is_url(text: str) -> bool:
    """True when ``text`` starts with a URL scheme (``https://``, ``file://``, ...); anything else
    is a local path."""
    return bool(re.match(r"^[A-Za-z][A-Za-z0-9+.-]*://", text))


@dataclass(frozen=True)
class Group:
    """Files of a benchmark folder sharing a path prefix and a story (where they come from)."""

    prefix: str  # "instances/", or a file name ("LICENSE")
    fetchable: bool
    required: bool = True
    note: str = ""
    #: made by ``DataFolder.generate`` after the download, not taken from a source
    generated: bool = False

    def holds(self, rel: str) -> bool:
        return rel == self.prefix or (self.prefix.endswith("/") and rel.startswith(self.prefix))


@dataclass(frozen=True)
class Source:
    """One file to download: its name at a mirror, its default URL, and how its content maps
    onto the folder (``archive``: zip or tar.gz members; else a single file saved as ``saves_as``)."""

    name: str
    url: str
    kind: str  # "zip", "tar.gz", "file", or "git" (a repository: ``ref`` is the pinned commit)
    saves_as: str = ""
    ref: str = ""

    def location(self, mirror: str | None) -> str:
        if mirror is None:
            return self.url
        if self.kind == "git":  # a mirror of a repository is the repository itself (a folder or a git URL)
            return mirror if is_url(mirror) else str(Path(mirror).expanduser())
        if is_url(mirror):
            return mirror.rstrip("/") + "/" + self.name
        return str(Path(mirror).expanduser() / self.name)


@dataclass(frozen=True)
class DataFolder:
    """One data folder of a benchmark: how it is found (``location``), what it holds, how to fetch it."""

    name: str  # "robotouille", "alfworld-2.1.2": the folder name in the caches and ``recap data``'s BENCH
    title: str  # "ALFWorld (game files 2.1.1)": used in ``recap data`` messages
    location: DataLocation
    groups: tuple[Group, ...]
    sources: tuple[Source, ...]
    #: member name in an archive -> path in the folder (None: not wanted)
    member_path: Callable[[str], str | None]
    after_fetch: str = ""  # printed after a successful fetch
    #: writes the ``generated`` groups into a folder holding the downloaded files; returns their paths
    generate: Callable[[Path], list[str]] | None = None
    #: the folder's own search when it does not follow the shared rule of workers/envs/data_paths.py
    #: (ALFWorld 2.1.2: option, variable, next to the ALFWorld folder): every rung and the one used
    search: Callable[[str | None], tuple[list[Rung], Rung | None]] | None = None
    #: part of ``recap data ... all``; False for a folder asked for by name only (the authors'
    #: released prompts: only ``prompts: release`` runs need it, so its absence fails nothing else)
    in_all: bool = True
    #: the folder's own fetch, for data whose bytes the repository cannot pin (SWE-bench Verified:
    #: a dataset read through a library, or a local copy): ``load(from_file or None, subset, folder,
    #: out)`` writes the files into the empty ``folder`` and returns their paths; ValueError for bad
    #: input (exit 2), any other exception when nothing can be read (exit 1). Such a folder carries
    #: its own ``MANIFEST.sha256``, written by the fetch, which ``recap data check`` verifies
    load: Callable[[str | None, bool, Path, TextIO], list[str]] | None = None
    #: extra lines ``recap data check`` prints for a verified folder (SWE-bench Verified: its images)
    check_notes: Callable[[Path], list[str]] | None = None

    def group_of(self, rel: str) -> Group:
        for group in self.groups:
            if group.holds(rel):
                return group
        return Group("", fetchable=False)
