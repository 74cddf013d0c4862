"""``recap data images swebench-verified``: list, pull or build the per-instance images the selected instances lack.

Each instance runs in the image the official harness names (:mod:`.images`). Two ways to get one:

* pull the published image (``swebench/sweb.eval.x86_64.<id with __ -> _1776_>:latest``) from Docker
  Hub through the Docker SDK (``client.images.pull(repo, tag)``), ``workers`` at a time; each pull
  is one printed line, ``pulled NAME`` or ``failed NAME: REASON`` (the daemon's own reason, on one
  line), in the order of the instances;
* build it with the harness itself (``swebench.harness.docker_build.build_instance_images``, the
  function ``python -m swebench.harness.prepare_images`` calls), from the stored records, without a
  namespace, so the image is ``sweb.eval.x86_64.<id>:latest``. The harness builds the base and
  environment images first (network: base images and packages), prints its progress and a
  traceback per failure; that text is captured, and only one line per instance is printed.

Which images are present is one listing before and one after (``client.images.list()``); the
command succeeds when every selected instance has its image at the end. Nothing here raises for a
failed pull or build: the failures are lines, and :class:`ImagesError` is for a command that
cannot start (the daemon unreachable, the harness not installed).
"""

from __future__ import annotations

import contextlib
import io
import re
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, TextIO

from recap.env import UnknownInstanceError

from .dataset import records as stored_records
from .images import TAG, image_of, local_image, present_tags, remote_image

#: the data folder whose instances have images (``recap data images BENCH``)
FOLDERS = ("swebench-verified",)
#: the harness's default number of parallel builds (prepare_images.py ``--max_workers``)
DEFAULT_WORKERS = 4
#: where the harness writes its build logs (swebench.harness.constants, relative to the current folder)
BUILD_LOGS = "logs/build_images/"
#: the longest reason printed for one image
REASON_CHARS = 240


class ImagesError(RuntimeError):
    """The command cannot start (the daemon unreachable, the harness missing): one line, exit 1."""


def reason(exc: BaseException) -> str:
    """One line for a failed pull or build: the daemon's explanation for an API error (not the
    HTTP wrapper around it), else the exception's first line; whitespace collapsed, capped."""
    explanation = getattr(exc, "explanation", None)
    text = str(explanation) if explanation else str(exc).split("\n", 1)[0]
    text = " ".join(text.split()) or type(exc).__name__
    return text if len(text) <= REASON_CHARS else text[: REASON_CHARS - 3] + "..."


def open_client(workers: int) -> Any:
    """A client of the local daemon with room for ``workers`` concurrent requests; ImagesError
    (one line) when it does not answer."""
    import docker
    import docker.errors

    try:
        client = docker.from_env(timeout=1800, max_pool_size=max(10, workers))
        client.ping()
    except docker.errors.DockerException as exc:
        raise ImagesError(f"the Docker daemon is unreachable ({reason(exc)})") from None
    return client


@dataclass(frozen=True)
class Selection:
    """The selected records and which of them lack their image."""

    records: tuple[Mapping[str, str], ...]
    missing: tuple[Mapping[str, str], ...]

    def header(self, folder: str) -> str:
        """The first line every mode prints: how many are selected, how many have their image."""
        n, k = len(self.records), len(self.missing)
        if not k:
            return f"{folder}: {n} instance{'s' if n != 1 else ''} selected, all with their image here"
        return f"{folder}: {n} instance{'s' if n != 1 else ''} selected, {n - k} with their image here, {k} missing"


def select(records: Sequence[Mapping[str, str]], present: set[str]) -> Selection:
    """Split the records by whether either of their image names is in ``present``."""
    missing = tuple(r for r in records if image_of(r["instance_id"], present) is None)
    return Selection(tuple(records), missing)


def _summary(folder: str, done: str, ok: int, failed: int, records: Sequence[Mapping[str, str]], present: set[str]) -> str:
    have = sum(image_of(r["instance_id"], present) is not None for r in records)
    return f"{folder}: {ok} {done}, {failed} failed; {have} of {len(records)} instances have their image here"


def pull(client: Any, folder: str, selection: Selection, workers: int, out: TextIO, dry_run: bool = False) -> list[str]:
    """Pull each missing published image, ``workers`` at a time, one line each in the instances'
    order; returns the failure lines (empty: every selected instance has its image at the end)."""
    names = [remote_image(r["instance_id"]) for r in selection.missing]
    if dry_run:
        for name in names:
            print(f"would pull {name}", file=out)
        print(f"{folder}: dry run: would pull {len(names)} image(s), {workers} at a time; nothing was pulled", file=out)
        return []

    def one(name: str) -> str | None:
        repo, _, tag = name.rpartition(":")
        try:
            client.images.pull(repo, tag)
        except Exception as exc:  # an API error, a timeout, a broken stream: the image's line says why
            return reason(exc)
        return None

    failed = []
    with ThreadPoolExecutor(max_workers=workers) as pool:
        for name, why in zip(names, pool.map(one, names)):  # map yields in order: the lines are deterministic
            print(f"pulled {name}" if why is None else f"failed {name}: {why}", file=out, flush=True)
            if why is not None:
                failed.append(name)
    present = present_tags(client)
    print(_summary(folder, "pulled", len(names) - len(failed), len(failed), selection.records, present), file=out)
    return _failures(selection, present, f"{len(failed)} of {len(names)} image(s) could not be pulled" if failed else "")


def _failures(selection: Selection, present: set[str], what: str) -> list[str]:
    still = [r for r in selection.records if image_of(r["instance_id"], present) is None]
    if not still:
        return []
    return [what or f"{len(still)} instance(s) still have no image here"]


# -- building with the harness ------------------------------------------------------------------
def _harness() -> tuple[Callable[..., Any], Callable[..., Any]]:
    """The harness's ``build_instance_images`` and ``make_test_spec`` (looked up at each call, so a
    test can replace them); ImagesError when swebench is not installed."""
    try:
        from swebench.harness import docker_build
        from swebench.harness.test_spec import test_spec
    except ImportError:
        raise ImagesError("the SWE-bench harness is not installed (pip install 'recap-eval[swe]')") from None
    return docker_build.build_instance_images, test_spec.make_test_spec


def spec_of(make_test_spec: Callable[..., Any], record: Mapping[str, str]) -> Any:
    """The harness's test spec of a stored record (namespace None: the locally built name); ValueError
    (one line) when the harness has no specification for its repository and version."""
    try:
        return make_test_spec(dict(record), namespace=None, instance_image_tag=TAG, env_image_tag=TAG)
    except KeyError:
        raise ValueError(
            f"the SWE-bench harness has no specification for {record['repo']} version {record['version']!r}"
        ) from None
    except Exception as exc:  # the harness's own checks (assertions, bad fields)
        raise ValueError(f"the SWE-bench harness cannot make its test spec: {reason(exc)}") from None


#: a failure the harness prints: ``<class '...BuildImageError'>: Error building image NAME: MESSAGE``
_BUILD_ERROR = re.compile(r"Error building image (\S+): (.*)")


def _printed_errors(text: str) -> dict[str, str]:
    """NAME -> the first line of its build error, from the harness's captured output."""
    found: dict[str, str] = {}
    for line in text.splitlines():
        m = _BUILD_ERROR.search(line)
        if m is not None:
            found.setdefault(m.group(1), " ".join(m.group(2).split())[:REASON_CHARS] or "failed")
    return found


def _build_reason(spec: Any, printed: dict[str, str]) -> str:
    for key in (spec.instance_image_key, spec.instance_id):
        if key in printed:
            return printed[key]
    if spec.env_image_key in printed:
        return f"its environment image {spec.env_image_key} failed to build: {printed[spec.env_image_key]}"
    return f"the harness did not build it (its log: {BUILD_LOGS}instances/{spec.instance_image_key.replace(':', '__')}/)"


def build(client: Any, folder: str, selection: Selection, workers: int, out: TextIO, dry_run: bool = False) -> list[str]:
    """Build each missing image with the harness (``build_instance_images``, ``workers`` at a time),
    one line each in the instances' order; returns the failure lines (empty: all present at the end)."""
    build_instance_images, make_test_spec = _harness()
    specs: list[tuple[Mapping[str, str], Any]] = []
    refused: dict[str, str] = {}
    for rec in selection.missing:
        try:
            specs.append((rec, spec_of(make_test_spec, rec)))
        except ValueError as exc:
            refused[rec["instance_id"]] = str(exc)
    if dry_run:
        for rec in selection.missing:
            name = local_image(rec["instance_id"])
            why = refused.get(rec["instance_id"])
            print(f"would build {name}" if why is None else f"cannot build {name}: {why}", file=out)
        print(
            f"{folder}: dry run: would build {len(specs)} image(s) with the SWE-bench harness, {workers} at a time; "
            "nothing was built",
            file=out,
        )
        return [f"{len(refused)} image(s) cannot be built by the harness"] if refused else []
    printed: dict[str, str] = {}
    crashed: str | None = None
    if specs:
        captured = io.StringIO()
        with contextlib.redirect_stdout(captured), contextlib.redirect_stderr(captured):
            try:
                build_instance_images(
                    client,
                    [dict(rec) for rec, _ in specs],
                    force_rebuild=False,
                    max_workers=workers,
                    namespace=None,
                    tag=TAG,
                    env_image_tag=TAG,
                )
            except Exception as exc:  # e.g. a base image that cannot be built: every instance fails with it
                crashed = reason(exc)
        printed = _printed_errors(captured.getvalue())
    present = present_tags(client)
    by_id = {rec["instance_id"]: spec for rec, spec in specs}
    failed = 0
    for rec in selection.missing:
        iid = rec["instance_id"]
        name = local_image(iid)
        if image_of(iid, present) is not None:
            print(f"built {name}", file=out)
            continue
        failed += 1
        why = refused.get(iid) or crashed or _build_reason(by_id[iid], printed)
        print(f"failed {name}: {why}", file=out)
    built = len(selection.missing) - failed
    print(_summary(folder, "built", built, failed, selection.records, present), file=out)
    if failed and specs:
        print(f"{folder}: the harness's build logs are under {BUILD_LOGS}", file=out)
    n = len(selection.missing)
    return _failures(selection, present, f"{failed} of {n} image(s) could not be built" if failed else "")


def listing(folder: str, selection: Selection, out: TextIO) -> list[str]:
    """No action: the missing images' published names; a failure line when some are missing."""
    for rec in selection.missing:
        print(f"missing {remote_image(rec['instance_id'])}", file=out)
    if not selection.missing:
        return []
    return [
        f"{len(selection.missing)} image(s) missing; get them with `recap data images {folder} --pull` "
        "(Docker Hub) or `--build` (the SWE-bench harness)"
    ]


def get_images(
    folder: str,
    records: Sequence[Mapping[str, str]],
    action: str | None,
    workers: int,
    out: TextIO,
    dry_run: bool = False,
) -> list[str]:
    """The command: one listing, the header, then list (``action`` None), ``pull`` or ``build``.
    Returns the failure lines; ImagesError when it cannot start."""
    client = open_client(workers)
    selection = select(records, present_tags(client))
    print(selection.header(folder), file=out, flush=True)
    if action is None:
        return listing(folder, selection, out)
    if not selection.missing:
        return []
    return (pull if action == "pull" else build)(client, folder, selection, workers, out, dry_run)


def selected_records(selectors: Sequence[str], data_dir: str | None = None) -> list[Mapping[str, str]]:
    """The stored records the selectors pick (as ``recap env list swe-verified`` takes them: ``all``,
    ``owner/name``, an instance id with or without ``swe-verified/``), each once, in the dataset's
    order; none: all. UnknownInstanceError for a selector of no such form (:func:`.benchmark.selector_problem`,
    checked before the data folder is looked for) or one that picks nothing; DataNotFoundError
    when there is no data folder."""
    from .benchmark import BENCHMARK, selector_problem

    for selector in selectors:
        if (problem := selector_problem(selector)) is not None:
            raise UnknownInstanceError(problem)
    recs = stored_records(data_dir)
    wanted: set[str] = set()
    for selector in selectors or ["all"]:
        wanted.update(i.partition("/")[2] for i in BENCHMARK.list_instances_for(selector, {"data_dir": data_dir}))
    return [r for r in recs if r["instance_id"] in wanted]
