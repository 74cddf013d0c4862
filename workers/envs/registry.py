"""One registry of benchmarks, so the CLI and the pipeline address any instance by id.

An instance id is ``<benchmark>/<rest>``, e.g. ``robotouille/asynchronous/5_potato_soup@42`` or
``alfworld/pick_heat_then_place_in_recep/...``. A benchmark is a :class:`Benchmark`: it lists
and makes its instances, and answers the few questions the pipeline has about it through
declared hooks with defaults (which options an agent style runs with, where its data lives),
so no caller switches on a benchmark's name or probes for optional attributes.

Benchmarks are kept in :data:`BENCHMARKS`, a :class:`recap.registry.Registry` (the mechanism
the methods use too), by name: a module path (the module exposes ``BENCHMARK``), a
:class:`Benchmark` or a zero-argument factory returning one. Nothing is imported or built until
the benchmark is first used, so a missing optional dependency (alfworld's ``textworld``)
affects only that benchmark. The built-in benchmarks are the table at the end of this module,
one line each, the one list of their names; Ray workers import this module too, so a benchmark
that runs on a cluster is registered there (a registration made at run time in the driver
process exists only in that process: the in-process executor and tests).
"""

from __future__ import annotations

import json
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from recap.config import AgentConfig, BenchmarkProtocol
from recap.env import DataNotFoundError, Environment, UnknownInstanceError
from recap.registry import Registry
from workers.envs.data_sources import DataFolder
from workers.envs.options import EnvOption

__all__ = [
    "BENCHMARKS",
    "DataNotFoundError",
    "UnknownInstanceError",
    "Benchmark",
    "EstimateFigures",
    "RunService",
    "register_benchmark",
    "unregister_benchmark",
    "registered_benchmark",
    "get_benchmark",
    "make_env",
    "split_id",
    "place_of",
    "benchmark_names",
    "data_folder",
    "data_folders",
    "data_env_vars",
    "register_data_folder",
]


@dataclass(frozen=True)
class RunService:
    """A run-wide Ray actor that every episode worker's environments of one benchmark share (FEVER:
    the per-host Wikipedia politeness limit). The driver starts one per run, named
    ``recap-<name>-<run id>-<hex>``, and tells the workers its name in ``env_var``; ``actor`` is
    ``"package.module:Class"`` of the Ray actor class, imported only when a run starts it."""

    name: str
    env_var: str
    actor: str


@dataclass(frozen=True)
class EstimateFigures:
    """What ``recap estimate`` needs of one instance, known without playing it: its optimal steps
    (None: unknown), its step cap, its rules text and about how many characters its first
    observation has, and whether methods show it a demonstration."""

    optimal_steps: int | None
    max_steps: int
    rules: str
    observation_chars: int
    demonstration: bool


class Benchmark(BenchmarkProtocol, ABC):
    """What the pipeline needs from a benchmark: two duties and hooks with defaults (those it
    inherits from :class:`recap.config.BenchmarkProtocol` say what the methods' profiles mean
    on it).

    Subclasses set ``name`` and implement :meth:`list_instances` and :meth:`make`; the hooks
    below return "nothing special" unless overridden, so a new benchmark only writes the ones
    it has something to say about.
    """

    name: str = ""
    #: its environments run in sandboxes (containers): a sweep's ``ray.sandboxes_per_node``
    #: bounds how many of its episode workers share a node
    sandboxed: bool = False

    @abstractmethod
    def list_instances(self, selector: str | None = None) -> list[str]:
        """Instance ids in a fixed order; ``selector`` narrows (split, task, task type...)."""

    @abstractmethod
    def make(self, instance_id: str, **options: Any) -> Environment:
        """A fresh environment for ``instance_id`` (options: step_multiplier, data_dir...)."""

    # -- hooks ----------------------------------------------------------------------------------
    def declared_options(self) -> Mapping[str, EnvOption]:
        """The options a sweep's ``environments[].options`` may give this benchmark, each with its
        kind (:mod:`workers.envs.options`: what an episode does, part of the unit id, or how it is
        run, not) and its default. Any other option is refused before anything runs. Default:
        none (a benchmark that declares nothing takes no option from a sweep)."""
        return {}

    def list_instances_for(self, selector: str | None, options: Mapping[str, Any]) -> list[str]:
        """:meth:`list_instances` for an environment entry whose ``make()`` options are
        ``options`` (a sweep's ``options: {data_dir: ...}`` lists that folder's instances).
        Default: the options do not change the list."""
        return self.list_instances(selector)

    def options_for_agent(self, style: str, config: AgentConfig | None = None) -> dict[str, Any]:
        """``make()`` options an agent ``style`` (``recap``, ``react``...) with its resolved
        settings ``config`` runs with unless the sweep sets them (ALFWorld: whether observations
        list the valid actions). Default: none."""
        return {}

    def refuses_method(self, method: str) -> str | None:
        """Why ``method`` (its name: ``adapt``...) cannot run on this benchmark, in one line, or
        None; preflight refuses a sweep that pairs them before anything runs (FEVER: the paper
        has no ADaPT result). Default: every method runs."""
        return None

    def preflight(self, instance_ids: Sequence[str], options: Mapping[str, Any]) -> str | None:
        """Why a sweep's ``instance_ids`` (all of one ``environments[]`` entry, with its ``make()``
        options) cannot run here, in one line, or None; checked before anything runs, in one
        go for all of them (SWE-bench Verified: one ``docker images`` listing for every
        instance's image). Default: nothing to check beyond opening one environment."""
        return None

    def run_needs(self, instance_ids: Sequence[str], options: Mapping[str, Any]) -> list[str]:
        """What a run of ``instance_ids`` (one ``environments[]`` entry, with its ``make()``
        options) still needs on this machine and does not have, one short phrase each (SWE-bench
        Verified: its images, the Docker daemon); empty when nothing is missing, or when the
        entry is refused for a reason of the sweep file's own (:meth:`preflight` says that one).
        ``recap estimate`` lists these and prices the plan anyway; :meth:`preflight` refuses a
        run for them. Default: nothing beyond the data folder."""
        return []

    def estimate_figures(self, instance_id: str, options: Mapping[str, Any]) -> EstimateFigures | None:
        """The figures ``recap estimate`` needs of ``instance_id`` when opening and resetting it
        costs too much to do for every instance of a sweep (ALFWorld: seconds per game), or None:
        the estimate opens it and measures. Default: None."""
        return None

    def refuses_run_folder(self, options: Mapping[str, Any], run_folder: Path) -> str | None:
        """Why the instances an ``environments[]`` entry's options name cannot run with their
        results in the local folder ``run_folder``, in one line, or None; checked before anything
        runs (``swe``: a task's repository that holds the run folder would be cloned, run folder
        and all, into each sandbox). Default: nothing to check."""
        return None

    def data_folders(self) -> Mapping[str, DataFolder]:
        """The data folders this benchmark reads, by folder name: how each is found, what it
        holds and where its files come from (``recap data list/check/fetch`` work on these).
        Default: none (generated instances, like blocksworld)."""
        return {}

    def run_services(self) -> tuple[RunService, ...]:
        """The run-wide actors this benchmark's environments share across Ray workers. Default: none."""
        return ()

    def owner_options(self, run_id: str, worker_id: str, episode_id: str) -> dict[str, Any]:
        """``make()`` options that tell an episode's environment who owns what it starts (the
        coding benchmark labels its sandboxes with them, so :meth:`remove_leftovers` finds what
        a killed worker left). Not part of a unit's settings: the same unit may run in any
        worker. Default: none."""
        return {}

    def remove_leftovers(self, run_id: str, worker_id: str | None = None) -> int:
        """Remove what this benchmark's environments left running for run ``run_id``: one
        worker's (its process died mid-episode) or, with ``worker_id`` None, every worker's (a
        session ends; a resume starts after a driver killed with SIGKILL). Returns how many
        things were removed. Default: environments start nothing that outlives them."""
        return 0

    def replay_file(self, path: str, options: Mapping[str, object]) -> tuple[bool, str]:
        """``recap env replay``: (identical?, message) for a recorded trajectory file of this
        benchmark, ``options`` overriding the file's own; raises ValueError for a file it cannot
        read. Default: this benchmark records no trajectories."""
        raise ValueError(f"{self.name} has no recorded-trajectory replay")

    def data_env_vars(self) -> tuple[str, ...]:
        """Environment variables that point at this benchmark's data; the driver forwards them
        to Ray workers. Default: the variables of :meth:`data_folders`."""
        return tuple(folder.location.env_var for folder in self.data_folders().values())

    def canonical_id(self, instance_id: str) -> str:
        """The one spelling of ``instance_id`` before an environment is made, so two spellings
        of one instance name one unit (Blocksworld: numbers without leading zeros); raises
        UnknownInstanceError for an id this benchmark can never make. After the environment is
        made, its own ``instance_id`` is the spelling. Default: as written."""
        return instance_id

    def place(self, instance_id: str, split: str | None = None, task: str | None = None) -> tuple[str, str]:
        """``(split, task)`` of an episode row of ``instance_id``, given what its environment
        reported (``None``: it reported nothing, e.g. a unit whose worker died before it made
        one). Default: what the environment reported, empty when nothing."""
        return split or "", task or ""


#: what register_benchmark accepts: "package.module" (exposing BENCHMARK), a Benchmark, or a factory
BenchmarkSource = str | Benchmark | Callable[[], Benchmark]


def _as_benchmark(name: str, source: object) -> Benchmark:
    """The Benchmark a registration resolves to (a factory is called), checked to call itself
    ``name``."""
    bench = source if isinstance(source, Benchmark) or not callable(source) else source()
    if not isinstance(bench, Benchmark):
        raise TypeError(f"benchmark {name!r} resolved to {bench!r}, which is not a workers.envs.registry.Benchmark")
    if bench.name != name:
        raise ValueError(f"benchmark registered as {name!r} calls itself {bench.name!r}")
    return bench


#: every benchmark by name, resolved on first use; :func:`benchmark_names` lists them
BENCHMARKS: Registry[Benchmark] = Registry(
    "benchmark", coerce=_as_benchmark, error=ValueError, unknown_error=UnknownInstanceError, attribute="BENCHMARK"
)


def register_benchmark(name: str, source: BenchmarkSource) -> None:
    """Make ``name`` addressable (``name/...`` instance ids). ``source`` is resolved on first
    use. A name is registered once; :func:`unregister_benchmark` first to replace it."""
    if not name or "/" in name:
        raise ValueError(f"benchmark name {name!r} must be non-empty and contain no '/'")
    if not isinstance(source, (str, Benchmark)) and not callable(source):
        raise TypeError(f"benchmark {name!r}: register a module path, a Benchmark or a factory, not {source!r}")
    BENCHMARKS.register(name, source)


def unregister_benchmark(name: str) -> None:
    """Forget ``name`` (tests register toy benchmarks and remove them again); KeyError if it is
    not registered."""
    if name not in BENCHMARKS:
        raise KeyError(name)
    BENCHMARKS.unregister(name)


@contextmanager
def registered_benchmark(name: str, source: BenchmarkSource) -> Iterator[None]:
    """:func:`register_benchmark` for the duration of a ``with`` block (as
    :func:`recap.methods.registered_method` for methods)."""
    register_benchmark(name, source)
    try:
        yield
    finally:
        unregister_benchmark(name)


def benchmark_names() -> list[str]:
    """Registered names, in registration order (built-ins first)."""
    return BENCHMARKS.names()


def get_benchmark(name: str) -> Benchmark:
    """The benchmark registered as ``name`` (imported/built on first use); UnknownInstanceError
    naming the known ones otherwise."""
    return BENCHMARKS.get(name)


def split_id(instance_id: str) -> tuple[str, str]:
    """``(benchmark, rest)`` of an instance id ``<benchmark>/<rest>``; raises UnknownInstanceError
    for an id without both parts."""
    bench, sep, rest = instance_id.partition("/")
    if not sep or not rest:
        raise UnknownInstanceError(
            f"instance id {instance_id!r} must look like <benchmark>/<instance>, benchmarks: {', '.join(benchmark_names())}"
        )
    return bench, rest


def place_of(instance_id: str, split: str | None = None, task: str | None = None) -> tuple[str, str, str]:
    """``(benchmark, split, task)`` of an episode row, as its benchmark places it
    (:meth:`Benchmark.place`); a benchmark not registered or not importable here places it by
    the default: what the environment reported. (Rows of schema version 1 are read by
    :func:`schemas.labels.place_of`, which cannot ask the benchmarks.)"""
    bench = instance_id.split("/", 1)[0]
    try:
        found = get_benchmark(bench)
    except (UnknownInstanceError, ImportError):
        return bench, split or "", task or ""
    return (bench, *found.place(instance_id, split, task))


def make_env(instance_id: str, **options: Any) -> Environment:
    """The environment of ``instance_id``, made by its benchmark with ``options``; raises
    UnknownInstanceError for an unknown benchmark."""
    bench, _ = split_id(instance_id)
    return get_benchmark(bench).make(instance_id, **options)


#: the benchmark of a trajectory file without a ``benchmark`` field: the real Robotouille engine's
#: recorded trajectories (../shared/data/robotouille) carry none
UNNAMED_TRAJECTORY_BENCHMARK = "robotouille"


def replay_trajectory_file(path: str, options: Mapping[str, object]) -> tuple[bool, str]:
    """(identical?, message) for a recorded trajectory, replayed by the benchmark its
    ``"benchmark"`` field names (:meth:`Benchmark.replay_file`); raises ValueError/OSError for a
    file that cannot be read, UnknownInstanceError for a benchmark nothing registers."""
    try:
        raw = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        raw = None  # unreadable or not JSON: the default benchmark's reader says what is wrong with it
    name = raw.get("benchmark") if isinstance(raw, dict) else None
    return get_benchmark(name if isinstance(name, str) else UNNAMED_TRAJECTORY_BENCHMARK).replay_file(path, options)


def _as_data_folder(name: str, obj: object) -> DataFolder:
    """The DataFolder a registration names, checked to be called ``name``."""
    if not isinstance(obj, DataFolder) or obj.name != name:
        raise TypeError(f"data folder {name!r}: {obj!r} is not a DataFolder named {name!r}")
    return obj


#: data folders no benchmark reads (the authors' released prompts), by name, imported on first use
#: read again at every use (``keep=False``): a folder is a module attribute that tests replace
EXTRA_FOLDERS: Registry[DataFolder] = Registry("data folder", coerce=_as_data_folder, error=ValueError, keep=False)


def register_data_folder(name: str, source: str) -> None:
    """Make a data folder that no benchmark declares known to ``recap data`` and to the workers'
    environment: ``source`` is ``"package.module:ATTRIBUTE"`` naming a DataFolder (imported on
    first use)."""
    EXTRA_FOLDERS.register(name, source)


def data_folders() -> dict[str, DataFolder]:
    """Every registered benchmark's data folders by name, in registration order, then the folders
    registered on their own (:func:`register_data_folder`). Imports the benchmarks; one that
    cannot be imported here declares nothing."""
    out: dict[str, DataFolder] = {}
    for name in benchmark_names():
        try:
            folders = get_benchmark(name).data_folders()
        except ImportError:
            continue
        for key, folder in folders.items():
            out.setdefault(key, folder)
    for key, folder in EXTRA_FOLDERS.items():
        out.setdefault(key, folder)
    return out


def data_folder(name: str) -> DataFolder:
    """The data folder ``name`` (``robotouille``, ``alfworld-2.1.2``...) of whichever registered
    benchmark declares it."""
    try:
        return data_folders()[name]
    except KeyError:
        raise KeyError(f"no registered benchmark reads a data folder {name!r}") from None


def data_env_vars() -> tuple[str, ...]:
    """Every registered benchmark's data variables, in registration order, without repeats
    (a benchmark that cannot be imported here contributes none)."""
    out: list[str] = []
    for name in benchmark_names():
        try:
            out.extend(get_benchmark(name).data_env_vars())
        except ImportError:
            continue
    out.extend(folder.location.env_var for folder in EXTRA_FOLDERS.values())
    return tuple(dict.fromkeys(out))


# -- the built-in benchmarks: the one place they are named ----------------------------------------
register_benchmark("blocksworld", "workers.envs.blocksworld")
register_benchmark("robotouille", "workers.envs.robotouille")
register_benchmark("alfworld", "workers.envs.alfworld")
register_benchmark("fever", "workers.envs.fever")
register_benchmark("swe", "workers.envs.swe")
register_benchmark("swe-verified", "workers.envs.swe_verified")
#: the authors' released prompt and demonstration files (``prompts: release``): read by no benchmark
register_data_folder("recap-release", "workers.release.folder:FOLDER")
