"""SWE-bench Verified for the registry: the 500 instances of the stored dataset, each in its harness image.

Instance ids are ``swe-verified/<instance_id>`` (``swe-verified/django__django-11099``), listed in
the dataset's order. Selectors: ``all``, a repository (``django/django``), an instance id (with or
without ``swe-verified/``). The records come from the data folder ``swebench-verified``
(``recap data fetch swebench-verified``; found by the shared rule, or ``options.data_dir``).

Options of :meth:`VerifiedBenchmark.make` (and a sweep's ``environments[].options``): ``data_dir``;
``sandbox`` (``docker`` only: the instance's image is a Docker image); ``network``;
``command_timeout_s``, ``max_timeouts_in_row``, ``output_bytes``, ``max_commands``, ``wall_time_s``, ``disk_bytes`` (the
repository folder's cap, default :data:`DEFAULT_DISK_BYTES`: the harness's repositories are larger
than the example tasks), ``total_output_bytes``, ``eval_timeout_s`` (the test run's bound under every grading); ``grading``
(``harness``, the default: the harness's own run_evaluation in the instance's image decides,
:mod:`.harness_eval`, as published SWE-bench numbers are made; ``both``, ``ours``, ``official``: the
harness's eval script runs in our clean copy of the image, its log graded by the harness's parser
and ours, see :mod:`workers.envs.swe.harness_script`); ``step_multiplier``/``seed``
(no effect); ``open_sandbox``/``sandbox_labels`` (as for ``swe``).

The methods, profiles and leftover removal are the ``swe`` benchmark's (this class extends it).
Preflight (:meth:`VerifiedBenchmark.preflight`) refuses a sweep whose instances lack their image
with one ``docker images`` listing, however many instances.

Where an episode runs (:mod:`.release_container`): ``container`` ``harness`` (the harness's image)
or ``release`` (the ReCAP release's ``python:3.11`` container, its diff graded in the harness's
image), by default the method's (:meth:`VerifiedBenchmark.options_for_agent`); ``release_image``
and ``repo_mirror``; ``network`` defaults to on in the ``release`` container (as the release ran),
off in the harness's.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Mapping, Sequence
from functools import partial
from typing import Any

from recap.config import AgentConfig
from recap.env import Environment, UnknownInstanceError
from recap.plural import count
from workers.envs.data_sources import DataFolder
from workers.envs.options import EnvOption, episode, run
from workers.envs.swe.benchmark import SweBenchmark, default_open_sandbox
from workers.envs.swe.env import DEFAULT_TOTAL_OUTPUT_BYTES
from workers.envs.swe.grading import GRADINGS, Grading, check_grading
from workers.envs.swe.instances import SweInstance, id_problem
from workers.sandbox.base import SandboxError, SandboxLimits, episode_failure

from . import harness
from .data_folders import FOLDER
from .dataset import FOLDER_NAME, ID_PATTERN, records
from .env import BENCHMARK_NAME, VerifiedEnvironment
from .harness_eval import HARNESS_GRADING, remove_harness_containers
from .images import how_to_get, image_of, local_images, missing_images
from .release_container import OPTIONS as CONTAINER_OPTIONS
from .release_container import RELEASE_IMAGE, ReleaseEnvironment, agent_options, missing_image, release_of

#: how to get the instances' images (`recap data check` lists which are here)
IMAGES_HINT = (
    "pull them (docker pull swebench/sweb.eval.x86_64.<id>:latest) or build them with the SWE-bench harness "
    "(python -m swebench.harness.prepare_images)"
)
#: the grading modes here: the coding env's three, and the harness's own full evaluation
VERIFIED_GRADINGS: tuple[Grading, ...] = (*GRADINGS, HARNESS_GRADING)
#: the default: the harness's own evaluation decides, as for a leaderboard submission
VERIFIED_DEFAULT_GRADING: Grading = HARNESS_GRADING
#: the repository folder's size cap (the harness's repositories with their builds run to a few hundred MB)
DEFAULT_DISK_BYTES = 4 << 30
_LIMITS = ("command_timeout_s", "output_bytes", "max_commands", "wall_time_s", "disk_bytes")
ACCEPTED = (
    "data_dir",
    "sandbox",
    "network",
    *_LIMITS,
    "total_output_bytes",
    "max_timeouts_in_row",
    "eval_timeout_s",
    "grading",
    "step_multiplier",
    "seed",
    *CONTAINER_OPTIONS,
    "sandbox_labels",
    "open_sandbox",
)
_LIMIT_DEFAULTS = SandboxLimits()
#: the options a sweep may give (:mod:`workers.envs.options`). What an episode does: the sandbox,
#: its network, the limits, the grading, the container and the release's image; those whose
#: default is the method's set-up (:func:`.release_container.agent_options`: the container, the
#: network, ReCAP's released tool limits) declare no default, so given at all they are in the id.
#: How it is run: where the records and the repositories (``repo_mirror``, the same commits) come from
VERIFIED_OPTIONS: Mapping[str, EnvOption] = {
    "data_dir": run(),
    "sandbox": episode("docker"),
    "network": episode(),
    "command_timeout_s": episode(),
    "output_bytes": episode(_LIMIT_DEFAULTS.output_bytes),
    "max_commands": episode(_LIMIT_DEFAULTS.max_commands),
    "wall_time_s": episode(),
    "disk_bytes": episode(DEFAULT_DISK_BYTES),
    "total_output_bytes": episode(DEFAULT_TOTAL_OUTPUT_BYTES),
    "max_timeouts_in_row": episode(),
    "eval_timeout_s": episode(None),
    "grading": episode(VERIFIED_DEFAULT_GRADING),
    "container": episode(),
    "release_image": episode(RELEASE_IMAGE),
    "repo_mirror": run(),
}
LOCAL_REFUSAL = (
    "swe-verified runs in the SWE-bench harness's per-instance Docker images (the repository and its "
    "environment are in the image): sandbox 'local' cannot run it; use sandbox: docker"
)


#: ``owner/name`` as GitHub spells a repository
REPO_SELECTOR = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*/[A-Za-z0-9][A-Za-z0-9_.-]*")
#: the longest selector quoted back in an error line
SELECTOR_SHOWN = 80


def shown(selector: str) -> str:
    """``selector`` as an error line quotes it: repr, cut to :data:`SELECTOR_SHOWN` characters."""
    return repr(selector if len(selector) <= SELECTOR_SHOWN else selector[: SELECTOR_SHOWN - 3] + "...")


def selector_problem(selector: str) -> str | None:
    """Why ``selector`` cannot select anything, by its form alone (no data folder needed), or None:
    ``all``, a repository ``owner/name``, or an instance id (``owner__repo-NUMBER``, with or
    without ``swe-verified/``) held to :func:`~workers.envs.swe.instances.id_problem`'s characters."""
    iid = selector.removeprefix(f"{BENCHMARK_NAME}/")
    if selector == "all" or (REPO_SELECTOR.fullmatch(selector) and ".." not in selector):
        return None
    if id_problem(iid) is None and ID_PATTERN.match(iid):
        return None
    return (
        f"{shown(selector)} is not a selector: all, a repository (owner/name) or an instance id "
        f"(owner__repo-NUMBER, as `recap env list {BENCHMARK_NAME}` prints them)"
    )


def _positive(name: str, value: Any, kind: type) -> Any:
    if isinstance(value, bool) or not isinstance(value, (int, float) if kind is float else int) or not value > 0:
        raise ValueError(f"{name} must be a positive {'number' if kind is float else 'integer'}, got {value!r}")
    return kind(value)


def as_instance(rec: Mapping[str, str], test_cmd: str) -> SweInstance:
    """A stored record as the coding environment's instance (no host repository: ``repo_path`` empty)."""
    extra = ("hints_text", "created_at", "version", "environment_setup_commit", "difficulty")
    return SweInstance(
        instance_id=rec["instance_id"],
        repo=rec["repo"],
        base_commit=rec["base_commit"],
        problem_statement=rec["problem_statement"],
        fail_to_pass=tuple(json.loads(rec["FAIL_TO_PASS"])),
        pass_to_pass=tuple(json.loads(rec["PASS_TO_PASS"])),
        patch=rec["patch"],
        test_patch=rec["test_patch"],
        repo_path="",
        test_cmd=test_cmd,
        extra={k: rec[k] for k in extra},
    )


class VerifiedBenchmark(SweBenchmark):
    """SWE-bench Verified's registry entry (see the module docstring)."""

    name = BENCHMARK_NAME

    def declared_options(self) -> Mapping[str, EnvOption]:
        """:data:`VERIFIED_OPTIONS`."""
        return VERIFIED_OPTIONS

    def data_folders(self) -> Mapping[str, DataFolder]:
        """The stored dataset (``swebench-verified``)."""
        return {FOLDER_NAME: FOLDER}

    def remove_leftovers(self, run_id: str, worker_id: str | None = None) -> int:
        """The episodes' sandboxes by label (as ``swe``), and the containers of ``grading: harness``
        evaluations by the harness's name for them (:func:`.harness_eval.harness_run_id`)."""
        return super().remove_leftovers(run_id, worker_id) + remove_harness_containers(run_id, worker_id)

    def options_for_agent(self, style: str, config: AgentConfig | None = None) -> dict[str, Any]:
        """The container of the set-up the method's paper number came from (ReCAP: ``release``;
        mini-SWE-agent: ``harness``, network on under 1.0.0's configuration), unless the sweep sets
        them (:func:`.release_container.agent_options`)."""
        return agent_options(style, config)

    def list_instances(self, selector: str | None = None) -> list[str]:
        """:meth:`list_instances_for` on the folder the shared rule finds."""
        return self.list_instances_for(selector, {})

    def list_instances_for(self, selector: str | None, options: Mapping[str, Any]) -> list[str]:
        """``None``/``all``: every instance in the dataset's order; ``owner/name``: that
        repository's; an instance id: that one; UnknownInstanceError otherwise."""
        recs = records(options.get("data_dir"))
        ids = [f"{BENCHMARK_NAME}/{r['instance_id']}" for r in recs]
        if selector in (None, "", "all"):
            return ids
        wanted = selector.removeprefix(f"{BENCHMARK_NAME}/")
        found = [i for i, r in zip(ids, recs) if r["repo"] == selector or r["instance_id"] == wanted]
        if not found:
            raise UnknownInstanceError(
                f"no SWE-bench Verified instance is {shown(selector)}; selectors: all, a repository (owner/name), an instance id"
            )
        return found

    def canonical_id(self, instance_id: str) -> str:
        """``swe-verified/<owner__repo-NUMBER>`` as written; UnknownInstanceError otherwise."""
        bench, _, rest = instance_id.partition("/")
        if bench != BENCHMARK_NAME or ID_PATTERN.match(rest) is None:
            raise UnknownInstanceError(
                f"a SWE-bench Verified instance id looks like {BENCHMARK_NAME}/owner__repo-NUMBER, got {instance_id!r}"
            )
        return instance_id

    def preflight(self, instance_ids: Sequence[str], options: Mapping[str, Any]) -> str | None:
        """Refuse a sweep that cannot run: a ``local`` sandbox, or instances whose image is not
        here (one ``docker images`` listing for all of them)."""
        if options.get("sandbox", "docker") == "local":
            return LOCAL_REFUSAL
        try:
            release = release_of(options)
        except ValueError as exc:
            return str(exc)
        if options.get("open_sandbox") is not None:
            return None
        try:
            present = local_images()
        except SandboxError as exc:
            return str(exc)
        if release is not None and (refusal := missing_image(release, present)) is not None:
            return refusal
        names = [i.partition("/")[2] for i in instance_ids]
        missing = missing_images(names, present)
        if missing:
            return f"{len(missing)} of {len(names)} instances have no image here (first: {missing[0]}); {IMAGES_HINT}"
        return None

    def run_needs(self, instance_ids: Sequence[str], options: Mapping[str, Any]) -> list[str]:
        """What :meth:`preflight` would refuse a run for that is about this machine, not the sweep
        file: the Docker daemon when it cannot be reached (then every image is counted as still
        needed: none can be listed), else the instances' images and the release container's image
        that are not here. Empty when the options themselves are refused (``preflight`` says why)."""
        if options.get("sandbox", "docker") == "local" or options.get("open_sandbox") is not None:
            return []
        try:
            release = release_of(options)
        except ValueError:
            return []
        names = [i.partition("/")[2] for i in instance_ids]
        try:
            present = local_images()
        except SandboxError:
            needs = [
                "the Docker daemon (unreachable: start it, `sudo systemctl start docker` or `sudo dockerd &`)",
                f"{count(len(names), 'instance image')} (not checked without the daemon; {IMAGES_HINT})",
            ]
            if release is not None:
                needs.append(f"the release container's image {release.image} (not checked)")
            return needs
        needs = []
        missing = missing_images(names, present)
        if missing:
            needs.append(f"{count(len(missing), 'instance image')} of {len(names)} ({IMAGES_HINT}; first: {missing[0]})")
        if release is not None and missing_image(release, present) is not None:
            needs.append(f"the release container's image {release.image} (docker pull {release.image})")
        return needs

    def make(self, instance_id: str, **options: Any) -> Environment:
        """A fresh environment for ``swe-verified/<instance_id>`` in its image (opened at reset)."""
        unknown = sorted(set(options) - set(ACCEPTED))
        if unknown:
            raise ValueError(f"unknown swe-verified option(s) {', '.join(unknown)}; accepted: {', '.join(ACCEPTED[:-2])}")
        self.canonical_id(instance_id)
        kind = options.get("sandbox", "docker")
        if kind == "local":
            raise ValueError(LOCAL_REFUSAL)
        if kind != "docker":
            raise ValueError(f"sandbox must be 'docker', got {kind!r}")
        release = release_of(options)
        network = options.get("network", release is not None)
        if not isinstance(network, bool):
            raise ValueError(f"network must be true or false, got {network!r}")
        limits = SandboxLimits(
            network=network,
            disk_bytes=DEFAULT_DISK_BYTES,
            **{k: _positive(k, options[k], float if k.endswith("_s") else int) for k in _LIMITS if k in options},
        )
        total = _positive("total_output_bytes", options.get("total_output_bytes", DEFAULT_TOTAL_OUTPUT_BYTES), int)
        in_row = options.get("max_timeouts_in_row")
        if in_row is not None:
            in_row = _positive("max_timeouts_in_row", in_row, int)
        eval_timeout = options.get("eval_timeout_s")
        if eval_timeout is not None:
            eval_timeout = _positive("eval_timeout_s", eval_timeout, float)
        opener: Callable[..., Any] | None = options.get("open_sandbox")
        if opener is not None and not callable(opener):
            raise ValueError(f"open_sandbox must be a callable SandboxSpec -> Sandbox, got {opener!r}")
        labels = options.get("sandbox_labels") or {}
        if not isinstance(labels, Mapping) or not all(isinstance(v, str) for v in labels.values()):
            raise ValueError(f"sandbox_labels must map label names to strings, got {labels!r}")
        wanted = instance_id.partition("/")[2]
        data_dir = options.get("data_dir")
        rec = next((r for r in records(data_dir) if r["instance_id"] == wanted), None)
        if rec is None:
            raise UnknownInstanceError(f"no SWE-bench Verified instance {wanted!r} in the stored dataset")
        inst = as_instance(rec, harness.test_cmd(rec["repo"], rec["version"]))
        try:
            image = image_of(wanted, local_images()) if opener is None else None
        except SandboxError as exc:  # the daemon failed: infrastructure when it is the service
            raise episode_failure(instance_id, "the images cannot be listed", exc) from exc
        if opener is None and image is None:
            missing = missing_images([wanted], set())
            raise SandboxError(f"the image of {wanted} is not here ({missing[0]}); get it with {how_to_get(missing)}")
        if release is not None:
            release.check_source(rec["repo"])
            if opener is None and (refusal := missing_image(release, local_images())) is not None:
                raise SandboxError(refusal)
        grading = check_grading(options.get("grading", VERIFIED_DEFAULT_GRADING), VERIFIED_GRADINGS)
        return (VerifiedEnvironment if release is None else partial(ReleaseEnvironment, release=release))(
            inst,
            opener if opener is not None else default_open_sandbox(kind),
            record=rec,
            grading=grading,
            split="test",
            limits=limits,
            image=image or "",
            total_output_bytes=total,
            max_timeouts_in_row=in_row,
            eval_timeout_s=eval_timeout,
            labels=labels,
        )


BENCHMARK = VerifiedBenchmark()
