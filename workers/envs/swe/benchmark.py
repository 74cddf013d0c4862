"""SWE-bench for the registry: list the records of a JSONL file, make one sandboxed environment.

Options of :meth:`SweBenchmark.make` (and of a sweep's ``environments[].options``):

- ``instances_file`` (required): the JSONL file of SWE-bench records (:mod:`.instances`); its stem
  is the episodes' split;
- ``sandbox``: ``docker`` (default: a container of a locally built image, no network) or ``local``
  (a temporary folder on this host, each command under bubblewrap: only when asked);
- ``sandbox_trust``: ``isolated`` (default) or ``none``. A ``local`` sandbox confines each command
  with bubblewrap (:mod:`workers.sandbox.bwrap`); where bubblewrap is missing or does not work,
  the sweep is refused in preflight unless it says ``none``: the model's commands then run on this
  host as this user, able to read, change or delete what it can (no isolation at all);
- ``image``: the docker image (built locally; no registry is reached);
- ``network``: network inside the sandbox (default false);
- ``command_timeout_s``, ``output_bytes``, ``max_commands``, ``wall_time_s``: the episode's limits
  (:class:`~workers.sandbox.base.SandboxLimits`); ``max_commands`` is the step cap;
- ``max_timeouts_in_row``: commands in a row that may run past ``command_timeout_s`` before the
  episode ends (default: no such limit; the release's SWE-agent: 3);
- ``total_output_bytes``: all observations' bytes together; ``eval_timeout_s``: the evaluation's
  test run (default: the record's, else 30 minutes);
- ``grading``: ``both`` (default: our evaluation and the official SWE-bench harness's grading of
  the same test log, the official verdict deciding success; ours alone without the ``swebench``
  package), ``official`` (refused without the package) or ``ours`` (:mod:`.grading`);
- ``step_multiplier`` and ``seed`` are accepted and have no effect (a fixed cap; no randomness);
- ``open_sandbox``: a callable ``SandboxSpec -> Sandbox`` a caller passes in (tests), used instead
  of ``sandbox``;
- ``sandbox_labels``: the labels of the sandbox (the episode worker sets them from
  :meth:`SweBenchmark.owner_options`: run, worker, episode), by which leftovers are removed.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from functools import lru_cache, partial
from pathlib import Path
from typing import Any

from recap.config import CODING_PROFILE, SETTING_BOUNDS, AgentConfig, ReCAPConfig
from recap.env import Environment, UnknownInstanceError
from workers.envs.options import EnvOption, episode, run
from workers.envs.registry import Benchmark, EstimateFigures
from workers.sandbox import LABEL_EPISODE, LABEL_RUN, LABEL_WORKER, check_ready, open_sandbox, remove_labelled
from workers.sandbox.base import SANDBOX_KINDS, SandboxLimits, SandboxSpec
from workers.sandbox.local_sandbox import TRUST_LEVELS

from .env import DEFAULT_TOTAL_OUTPUT_BYTES, OpenSandbox, SweEnvironment
from .grading import DEFAULT_GRADING, check_grading
from .instances import BENCHMARK_NAME, SweInstance, load_instances

INSTANCES_FILE = "instances_file"
#: methods that cannot act in a repository, with the one-line reason a sweep is refused with
REFUSED_METHODS = {
    "cot": "CoT writes one plan before any observation and cannot run commands in a repository (the paper has no SWE-bench CoT)",
    "standard": "Standard writes one plan before any observation and cannot run commands in a repository (the paper has no SWE-bench Standard)",
    "act": "the paper's SWE-bench baseline is ReAct (mini-SWE-agent); it reports no Act result (Table 1: --)",
    "adapt": "the paper reports no ADaPT result on SWE-bench (Table 1: --)",
}
#: ReCAP on SWE-bench as the release ran it (GitHub ``ReCAP-Stanford/ReCAP`` at 2fb112f):
#: a $10 per-instance cap (swebench-recap/run_swe_bench_tasks.py:87; a sweep's ``limits.usd``
#: still wins); the whole history, no window (config/recap.yaml:142-144 has only a cache-control
#: processor), and a context overflow ends the episode (sweagent/agent/agents.py:1272-1276), its
#: diff handed in; exactly one tool call per reply (sweagent/tools/parsing.py:439-449); the reply
#: under a strict JSON schema (sweagent/agent/models.py:707-731)
RELEASED_RECAP: dict[str, Any] = {
    "max_episode_cost_usd": 10.0,
    "window": int(SETTING_BOUNDS["window"][1]),
    "window_counts_pins": True,
    "context_overflow": "end",
    "tool_calls_per_reply": "one",
    "reply_schema": True,
}
_LIMIT_OPTIONS = ("command_timeout_s", "output_bytes", "max_commands", "wall_time_s")
ACCEPTED = (
    INSTANCES_FILE,
    "sandbox",
    "sandbox_trust",
    "image",
    "network",
    *_LIMIT_OPTIONS,
    "total_output_bytes",
    "max_timeouts_in_row",
    "eval_timeout_s",
    "grading",
    "step_multiplier",
    "seed",
    "sandbox_labels",
    "open_sandbox",
)


_LIMIT_DEFAULTS = SandboxLimits()
#: the options a sweep may give (:mod:`workers.envs.options`). What an episode does: the sandbox
#: kind and image, its network, every limit, the grading. How it is run: where the records are
#: read from (as a data folder) and ``sandbox_trust``, a permission (to run commands unconfined
#: where bubblewrap does not work), not a setting: where bubblewrap works, commands are confined
#: whatever it says
SWE_OPTIONS: Mapping[str, EnvOption] = {
    INSTANCES_FILE: run(),
    "sandbox": episode("docker"),
    "sandbox_trust": run(),
    "image": episode(SandboxSpec.image),
    "network": episode(_LIMIT_DEFAULTS.network),
    **{k: episode(getattr(_LIMIT_DEFAULTS, k)) for k in _LIMIT_OPTIONS},
    "total_output_bytes": episode(DEFAULT_TOTAL_OUTPUT_BYTES),
    "max_timeouts_in_row": episode(None),
    "eval_timeout_s": episode(None),
    "grading": episode(DEFAULT_GRADING),
}


def _file_key(path: str | os.PathLike[str]) -> tuple[str, int, int]:
    p = Path(path).expanduser().resolve()
    try:
        st = p.stat()
    except FileNotFoundError:
        raise FileNotFoundError(f"SWE-bench instances file {p} does not exist") from None
    return str(p), st.st_size, st.st_mtime_ns


@lru_cache(maxsize=16)
def _load(path: str, size: int, mtime_ns: int) -> tuple[SweInstance, ...]:
    return tuple(load_instances(path))


def instances_of(options: Mapping[str, Any]) -> tuple[Path, tuple[SweInstance, ...]]:
    """The instances file ``options`` names and its records (read once while the file is unchanged)."""
    path = options.get(INSTANCES_FILE)
    if path is None:
        raise ValueError(f"swe needs options.{INSTANCES_FILE}: a JSONL file of SWE-bench records, each with a repo_path")
    if not isinstance(path, (str, os.PathLike)) or not str(path).strip():
        raise ValueError(f"{INSTANCES_FILE} must be a file path, got {path!r}")
    key = _file_key(path)
    return Path(key[0]), _load(*key)


def _positive(name: str, value: Any, kind: type) -> Any:
    if isinstance(value, bool) or not isinstance(value, (int, float) if kind is float else int) or not value > 0:
        noun = "number" if kind is float else "integer"
        raise ValueError(f"{name} must be a positive {noun}, got {value!r}")
    return kind(value)


def default_open_sandbox(kind: str, trust: str | None = None) -> OpenSandbox:
    """:func:`workers.sandbox.open_sandbox` bound to ``kind`` and the sweep's ``sandbox_trust``."""
    return partial(open_sandbox, kind, trust=trust)


class SweBenchmark(Benchmark):
    """SWE-bench's registry entry: records from ``options.instances_file``, episodes in a sandbox."""

    name = BENCHMARK_NAME
    sandboxed = True

    def declared_options(self) -> Mapping[str, EnvOption]:
        """:data:`SWE_OPTIONS`."""
        return SWE_OPTIONS

    def owner_options(self, run_id: str, worker_id: str, episode_id: str) -> dict[str, Any]:
        """The sandbox's labels: the run, the worker and the episode that own it."""
        return {"sandbox_labels": {LABEL_RUN: run_id, LABEL_WORKER: worker_id, LABEL_EPISODE: episode_id}}

    def remove_leftovers(self, run_id: str, worker_id: str | None = None) -> int:
        """Remove the sandboxes (containers, local process groups and folders) the run's workers,
        or one of them, left: :func:`workers.sandbox.remove_labelled` by their labels."""
        labels = {LABEL_RUN: run_id, **({LABEL_WORKER: worker_id} if worker_id is not None else {})}
        return remove_labelled(labels)

    def profile_settings(
        self, config_cls: type[AgentConfig], profile: str, ablation: str | None, generic: dict[str, Any]
    ) -> dict[str, Any]:
        """Every profile on SWE-bench runs at temperature 0 (the paper's SWE-bench protocol:
        :data:`recap.config.CODING_PROFILE`), beside what the profile sets anywhere; ReCAP under
        ``released`` as swebench-recap ran it (:data:`RELEASED_RECAP`)."""
        out = {**generic, **CODING_PROFILE}
        if profile == "released" and issubclass(config_cls, ReCAPConfig):
            out.update(RELEASED_RECAP)
        return out

    def refuses_method(self, method: str) -> str | None:
        """CoT, Standard, Act, ADaPT: see :data:`REFUSED_METHODS`; ReCAP and ReAct run."""
        return REFUSED_METHODS.get(method)

    def list_instances(self, selector: str | None = None) -> list[str]:
        """Always refused: the records come from ``options.instances_file``."""
        return self.list_instances_for(selector, {})

    def list_instances_for(self, selector: str | None, options: Mapping[str, Any]) -> list[str]:
        """``None``/``all``: every record in file order; ``owner/name``: that repository's; an
        instance id (with or without ``swe/``): that one; UnknownInstanceError otherwise."""
        path, insts = instances_of(options)
        if selector in (None, "", "all"):
            return [i.id for i in insts]
        wanted = selector.removeprefix(f"{BENCHMARK_NAME}/")
        found = [i.id for i in insts if i.repo == selector or i.instance_id == wanted]
        if not found:
            raise UnknownInstanceError(
                f"no SWE-bench record in {path} is {selector!r}; selectors: all, a repository (owner/name), an instance id"
            )
        return found

    def refuses_run_folder(self, options: Mapping[str, Any], run_folder: Path) -> str | None:
        """A task whose ``repo_path`` is the run folder or a folder above it: its clone would carry
        the run's own files (records, logs) into the model's sandbox. One line naming the first
        (the task and the repository first: preflight cuts a long line at its end)."""
        if options.get(INSTANCES_FILE) is None:  # swe-verified: the repositories are in the images
            return None
        path, insts = instances_of(options)
        run = run_folder.expanduser().resolve()
        for inst in insts:
            repo = Path(inst.repo_path)
            if repo == run or repo in run.parents:
                return f"the run folder is inside {inst.instance_id}'s repo_path {repo}: put output: outside it"
        return None

    def canonical_id(self, instance_id: str) -> str:
        """``swe/<instance_id>`` as written; UnknownInstanceError for an id without one."""
        bench, _, rest = instance_id.partition("/")
        if bench != BENCHMARK_NAME or not rest or any(c.isspace() for c in rest):
            raise UnknownInstanceError(f"a SWE-bench instance id looks like swe/<instance_id>, got {instance_id!r}")
        return instance_id

    def estimate_figures(self, instance_id: str, options: Mapping[str, Any]) -> EstimateFigures:
        """The estimate's figures from the environment made with a sandbox opener that is never
        called: a sandbox per instance (SWE-bench Verified: a container of its image) is not
        opened to price a sweep, and the daemon and images are not needed (``run_needs`` lists
        them). The first observation is the issue text; the cap is ``max_commands``."""

        def never(*_a: Any, **_k: Any) -> Any:
            raise AssertionError("recap estimate opens no sandbox")

        env: Any = self.make(instance_id, **{**options, "open_sandbox": never})
        return EstimateFigures(None, env.max_steps, env.rules(), len(env.instance.problem_statement), False)

    def make(self, instance_id: str, **options: Any) -> Environment:
        """A fresh environment for ``swe/<instance_id>`` (no sandbox is opened before reset);
        ValueError for an unknown or bad option, UnknownInstanceError for an id the file lacks."""
        unknown = sorted(set(options) - set(ACCEPTED))
        if unknown:
            raise ValueError(f"unknown swe option(s) {', '.join(unknown)}; accepted: {', '.join(ACCEPTED[:-2])}")
        self.canonical_id(instance_id)
        path, insts = instances_of(options)
        kind = options.get("sandbox", "docker")
        if kind not in SANDBOX_KINDS:
            raise ValueError(
                f"sandbox must be 'docker' or 'local' ('local' runs the model's commands on this host as this user: "
                f"it is not isolation), got {kind!r}"
            )
        trust = options.get("sandbox_trust")
        if trust is not None and trust not in TRUST_LEVELS:
            raise ValueError(
                f"sandbox_trust must be 'isolated' (a local sandbox confines commands with bubblewrap) or 'none' "
                f"(a local sandbox may run them unconfined on this host), got {trust!r}"
            )
        image = options.get("image", SandboxSpec.image)
        if not isinstance(image, str) or not image.strip():
            raise ValueError(f"image must be a docker image name, got {image!r}")
        network = options.get("network", False)
        if not isinstance(network, bool):
            raise ValueError(f"network must be true or false, got {network!r}")
        limits = SandboxLimits(
            network=network,
            **{k: _positive(k, options[k], float if k.endswith("_s") else int) for k in _LIMIT_OPTIONS if k in options},
        )
        total = _positive("total_output_bytes", options.get("total_output_bytes", DEFAULT_TOTAL_OUTPUT_BYTES), int)
        in_row = options.get("max_timeouts_in_row")
        if in_row is not None:
            in_row = _positive("max_timeouts_in_row", in_row, int)
        eval_timeout = options.get("eval_timeout_s")
        if eval_timeout is not None:
            eval_timeout = _positive("eval_timeout_s", eval_timeout, float)
        grading = check_grading(options.get("grading", DEFAULT_GRADING))
        opener: Callable[..., Any] | None = options.get("open_sandbox")
        if opener is not None and not callable(opener):
            raise ValueError(f"open_sandbox must be a callable SandboxSpec -> Sandbox, got {opener!r}")
        labels = options.get("sandbox_labels") or {}
        if not isinstance(labels, Mapping) or not all(isinstance(v, str) for v in labels.values()):
            raise ValueError(f"sandbox_labels must map label names to strings, got {labels!r}")
        if opener is None:
            # the daemon and the image, checked when the environment is made: a sweep's preflight
            # refuses a missing image before any episode (or any money) starts
            check_ready(kind, image, trust=trust)
        wanted = instance_id.partition("/")[2]
        inst = next((i for i in insts if i.instance_id == wanted), None)
        if inst is None:
            raise UnknownInstanceError(f"no SWE-bench record {wanted!r} in {path}")
        return SweEnvironment(
            inst,
            opener if opener is not None else default_open_sandbox(kind, trust),
            split=path.stem or "custom",
            limits=limits,
            image=image,
            total_output_bytes=total,
            max_timeouts_in_row=in_row,
            eval_timeout_s=eval_timeout,
            labels=labels,
            grading=grading,
        )


BENCHMARK = SweBenchmark()
