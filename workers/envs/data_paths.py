"""One rule for finding a benchmark's data folder, shared by the library, the CLI and the scripts.

The benchmark data never lives in this repository. Every entry point (``BENCHMARK.make``,
``recap env ...``, ``recap run`` and its Ray workers, ``recap data ...``, and so the scripts,
which call these) finds a benchmark's folder with :func:`search`, in this order; the first
folder that qualifies wins:

1. the explicit option: ``data_dir=...`` of ``make()`` / a sweep, ``--data-dir`` of ``recap data``;
2. the benchmark's environment variable (``ROBOTOUILLE_DATA``, ``ALFWORLD_DATA``);
3. the cache the upstream project itself downloads to: ALFWorld's ``alfworld-download`` writes
   to ``$ALFWORLD_DATA``, default ``~/.cache/alfworld`` (``alfworld/info.py`` of alfworld 0.4.2);
   Robotouille has none (its data sits inside its repository checkout);
4. recap-eval's own cache, where ``recap data fetch`` writes: ``$RECAP_EVAL_CACHE/data/<benchmark>``,
   default ``~/.cache/recap-eval/data/<benchmark>``;
5. the checkout-relative folder ``<checkout>/../shared/data/<benchmark>`` (the layout the
   scripts and the tests have always used).

Steps 1-2 are *explicit*: a folder named there must have the benchmark's layout, otherwise it
is an error (never a silent fall-through to another copy). Steps 3-5 are *probed*: a folder
that is absent, lacks the layout or fails the benchmark's extra probe (ALFWorld: game files in
the wrong wording version) is skipped, and the reason is kept for ``recap data list`` and for
the error message when nothing qualifies. Resolution only looks (``stat`` and at most one small
read); it never creates a folder.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from recap.env import DataNotFoundError

#: ``<checkout>/../shared/data``: the repository root is two levels above this package folder
CHECKOUT_DATA_ROOT = Path(__file__).resolve().parents[2].parent / "shared" / "data"
#: moves recap-eval's cache (shared with the run-folder mirror, pipeline/mirror.py)
CACHE_ENV = "RECAP_EVAL_CACHE"


def recap_cache_root() -> Path:
    """``$RECAP_EVAL_CACHE/data``, default ``~/.cache/recap-eval/data``."""
    base = os.environ.get(CACHE_ENV)
    return (Path(base).expanduser() if base else Path.home() / ".cache" / "recap-eval") / "data"


def checkout_data_root() -> Path:
    """``<checkout>/../shared/data``: the last place a benchmark folder is looked for, one folder
    beside the checkout that several checkouts share."""
    return CHECKOUT_DATA_ROOT


@dataclass(frozen=True)
class DataLocation:
    """How one benchmark's folder is recognised and where it is looked for."""

    name: str  # "robotouille": the folder name in the caches and in ../shared/data
    title: str  # "Robotouille": used in messages
    env_var: str  # "ROBOTOUILLE_DATA"
    marker: str  # a relative path every folder of this benchmark has
    upstream_cache: str | None = None  # "~/.cache/alfworld" (expanded at search time)
    upstream_note: str = "none"  # shown by `recap data list` when there is no upstream cache
    #: extra check for probed folders: None when it qualifies, else why it is skipped
    probe: Callable[[Path], str | None] | None = None


@dataclass(frozen=True)
class Rung:
    """One step of the search, as ``recap data list`` prints it."""

    step: str  # "data_dir", "$ROBOTOUILLE_DATA", "upstream cache", "recap-eval cache", "checkout"
    path: Path | None  # None: not given / not set / no such step for this benchmark
    explicit: bool
    status: str  # "not given", "not set", "found", "absent", "skipped: ...", "invalid: ..."

    @property
    def found(self) -> bool:
        return self.status == "found"


class ExplicitDataDirError(DataNotFoundError):
    """A folder named explicitly (option or environment variable) lacks the benchmark's layout."""

    def __init__(self, message: str, rung: Rung):
        super().__init__(message)
        self.rung = rung


def _layout_problem(loc: DataLocation, path: Path) -> str | None:
    if not path.is_dir():
        return "absent"
    if not (path / loc.marker).exists():
        return f"no {loc.marker}"
    return None


def search(loc: DataLocation, data_dir: str | os.PathLike[str] | None = None, *, stop_at_first: bool = True) -> list[Rung]:
    """The rungs of the search in order; the last one is ``found`` if a folder qualified.

    With ``stop_at_first=False`` every rung is evaluated (``recap data list`` shows them all;
    only the first ``found`` one is used).
    """
    rungs: list[Rung] = []

    def done() -> bool:
        # an explicitly named bad folder ends the search too: it is an error, not a miss
        return stop_at_first and bool(rungs) and (rungs[-1].found or rungs[-1].status.startswith("invalid"))

    # 1. the explicit option
    if data_dir is None:
        rungs.append(Rung("data_dir", None, True, "not given"))
    else:
        path = Path(data_dir).expanduser()
        problem = _layout_problem(loc, path)
        rungs.append(Rung("data_dir", path, True, "found" if problem is None else f"invalid: {problem}"))
    if done():
        return rungs
    # 2. the environment variable
    raw = os.environ.get(loc.env_var)
    if not raw:
        rungs.append(Rung(f"${loc.env_var}", None, True, "not set"))
    else:
        path = Path(raw).expanduser()
        problem = _layout_problem(loc, path)
        rungs.append(Rung(f"${loc.env_var}", path, True, "found" if problem is None else f"invalid: {problem}"))
    if done():
        return rungs
    # 3-5. the probed folders
    probed = [
        ("upstream cache", Path(loc.upstream_cache).expanduser() if loc.upstream_cache else None),
        ("recap-eval cache", recap_cache_root() / loc.name),
        ("checkout", checkout_data_root() / loc.name),
    ]
    for step, probe_path in probed:
        if probe_path is None:
            rungs.append(Rung(step, None, False, loc.upstream_note))
            continue
        path = probe_path
        problem = _layout_problem(loc, path)
        if problem is None and loc.probe is not None:
            reason = loc.probe(path)
            problem = f"skipped: {reason}" if reason else None
        elif problem is not None and problem != "absent":
            problem = f"skipped: {problem}"
        rungs.append(Rung(step, path, False, "found" if problem is None else problem))
        if done():
            return rungs
    return rungs


def first_explicit_error(rungs: list[Rung]) -> Rung | None:
    """The first explicit rung naming a bad folder, if it comes before any found folder."""
    for rung in rungs:
        if rung.found:
            return None
        if rung.status.startswith("invalid"):
            return rung
    return None


def chosen(rungs: list[Rung]) -> Rung | None:
    """The rung whose folder is used: the first found one, unless a bad explicit one precedes."""
    for rung in rungs:
        if rung.found:
            return rung
        if rung.status.startswith("invalid"):
            return None
    return None


def describe_probed(rungs: list[Rung]) -> str:
    """``~/.cache/alfworld: absent; /x/y: skipped: ...`` for the probed rungs with a path."""
    parts = [f"{r.path}: {r.status}" for r in rungs if not r.explicit and r.path is not None]
    return "; ".join(parts)


def resolve(
    loc: DataLocation,
    data_dir: str | os.PathLike[str] | None,
    *,
    invalid: Callable[[Path, str, str], str],
    missing: Callable[[list[Rung]], str],
) -> tuple[Path, Rung]:
    """The folder to use (resolved) and the rung it came from.

    ``invalid(path, source, problem)`` words the error for an explicitly named bad folder
    (``source`` is ``data_dir`` or the variable's name); ``missing(rungs)`` words the error when
    nothing qualifies. Both raise DataNotFoundError (ExplicitDataDirError for the first).
    """
    rungs = search(loc, data_dir)
    used = chosen(rungs)
    if used is not None:
        assert used.path is not None
        return used.path.resolve(), used
    bad = first_explicit_error(rungs)
    if bad is not None:
        assert bad.path is not None
        source = bad.step.lstrip("$")
        raise ExplicitDataDirError(invalid(bad.path, source, bad.status.removeprefix("invalid: ")), bad)
    raise DataNotFoundError(missing(rungs))
