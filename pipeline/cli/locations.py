"""Run-folder arguments of the ``recap`` commands: object-store folders checked once, pulled to a local copy.

``recap run``/``resume``/``status``/``show`` check an object-store location (bounded in time)
before anything touches it; ``recap sql`` and ``recap report`` read local folders only, so each
run-folder argument that is a URI is pulled to its local mirror first (:func:`local_run_dir`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from pipeline.cli.common import CHECKED_LOCATIONS
from pipeline.errors import PipelineError
from pipeline.spec import URI_SCHEMES, check_output_location
from pipeline.store import RUN_FILE, RunStore
from workers.sink import is_uri

#: turns one run-folder argument into a local folder (:func:`local_run_dir`, or none in tests)
Resolver = Callable[[str], str]


def check_location(location: str) -> None:
    """An object-store run folder must answer (bounded in time) before anything touches it;
    checked once per location and command (``main`` forgets the checks of the last command)."""
    if location not in CHECKED_LOCATIONS:
        check_output_location(location)
        CHECKED_LOCATIONS.add(location)


def local_run_dir(arg: str) -> str:
    """One run-folder argument of ``recap sql`` / ``recap report`` as a local folder: an object-store
    run is pulled to its local mirror first. Called for run-folder arguments only (never for a
    query, a title or an output folder); its errors are one line (RunDirError)."""
    from pipeline.mirror import mirror_dir, pull  # pyarrow and DuckDB: only the commands that read runs
    from reports.views import RunDirError

    if not is_uri(arg):
        return arg
    scheme = arg.split("://", 1)[0].lower()
    if scheme not in URI_SCHEMES:
        raise RunDirError(
            f"{arg} is not a run folder: unknown URI scheme {scheme!r} (a local folder or {', '.join(s + '://' for s in URI_SCHEMES)})"
        )
    try:
        check_location(arg)
        if not RunStore(arg).exists(RUN_FILE):
            raise RunDirError(f"{arg} is not a run folder (no {RUN_FILE})")
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


def run_folders(raw: Sequence[str], resolve: Resolver | None) -> list[str]:
    """The run-folder arguments, each made local by ``resolve`` and checked (RunDirError, one line)."""
    from reports.views import resolve_run_dirs

    local = [resolve(r) if resolve is not None else r for r in raw]
    resolve_run_dirs(local)
    return local
