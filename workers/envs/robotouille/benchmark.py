"""The Robotouille benchmark as the registry sees it: list instances, make environments.

``make(instance_id, step_multiplier=4.0, data_dir=None, engine="ours")`` reads the instance file
``instances/<split>/<task>_<seed>.json`` from the data folder and builds our engine on its
``generated_environment_json`` (the exact problem the real engine's seeded generator produced).
``engine="real"`` wraps the real ``robotouille`` package instead, when it is installed.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from recap.config import AgentConfig
from recap.env import Demonstration, Environment
from workers.envs.data_sources import DataFolder
from workers.envs.options import EnvOption, episode, run
from workers.envs.registry import Benchmark

from . import catalog, protocol
from .data import DataFileError, instance_path, read_json, require, resolve_data_dir, train_instance_path
from .data_folders import FOLDER
from .demo import DEMO_SEED, DEMO_SPLIT, DEMO_TASK, make_demonstration
from .domain import load_domain
from .env import RobotouilleEnv
from .replay import replay_file

ENGINES = ("ours", "real")
#: the options a sweep may give (:mod:`workers.envs.options`): the engine changes what an
#: episode does, the data folder only where the instances are read from
ROBOTOUILLE_OPTIONS: Mapping[str, EnvOption] = {"data_dir": run(), "engine": episode("ours")}
#: step cap of the demonstration kitchen (it is in no benchmark list, so has no optimal count)
DEMO_MAX_STEPS = 100


class RobotouilleBenchmark(Benchmark):
    """Robotouille's registry entry: the catalog's instances, made on our engine from the data
    folder (``engine="real"``: on the upstream package, when installed)."""

    name = catalog.BENCHMARK_NAME

    def declared_options(self) -> Mapping[str, EnvOption]:
        """:data:`ROBOTOUILLE_OPTIONS`."""
        return ROBOTOUILLE_OPTIONS

    def replay_file(self, path: str, options: Mapping[str, object]) -> tuple[bool, str]:
        """A trajectory the real engine recorded, replayed on ours (:mod:`.replay`); it takes no options."""
        if options:
            raise ValueError(f"--option applies to FEVER trajectories only, got {', '.join(sorted(options))}")
        return replay_file(path)

    def data_folders(self) -> Mapping[str, DataFolder]:
        """The data folder (:mod:`.data_folders`): found by the shared rule, fetched from upstream."""
        return {FOLDER.name: FOLDER}

    def place(self, instance_id: str, split: str | None = None, task: str | None = None) -> tuple[str, str]:
        """``synchronous``/``asynchronous`` and the environment's name, from the id
        (``robotouille/synchronous/6_lettuce_tomato_cheeseburger@42``) when the environment did
        not say (a unit whose worker died before it made one)."""
        parts = instance_id.split("/")
        if len(parts) > 2:
            return split or parts[1], task or parts[2].split("@", 1)[0]
        return split or "", task or ""

    def profile_settings(
        self, config_cls: type[AgentConfig], profile: str, ablation: str | None, generic: dict[str, Any]
    ) -> dict[str, Any]:
        """The methods' profiles on Robotouille (:mod:`.protocol`)."""
        return protocol.profile_settings(config_cls, profile, generic)

    def release_prompt_settings(self, config_cls: type[AgentConfig]) -> dict[str, Any]:
        """What the authors' released Robotouille prompts imply (:mod:`.protocol`)."""
        return protocol.release_prompt_settings(config_cls)

    def list_instances(self, selector: str | None = None) -> list[str]:
        return [ref.instance_id for ref in catalog.select(selector)]

    def make(self, instance_id: str, **options: Any) -> Environment:
        step_multiplier = float(options.pop("step_multiplier", 4.0))
        data_dir = options.pop("data_dir", None)
        engine = options.pop("engine", "ours")
        if options:
            raise TypeError(f"unknown Robotouille option(s): {', '.join(sorted(options))}")
        if engine not in ENGINES:
            raise ValueError(f"unknown Robotouille engine {engine!r}; engines: {', '.join(ENGINES)}")
        ref = catalog.parse_id(instance_id)
        if engine == "real":
            from .real_engine import make_real_env

            return make_real_env(ref, step_multiplier=step_multiplier)
        root = resolve_data_dir(data_dir)
        return make_instance_env(root, ref, step_multiplier)


def make_instance_env(root: Path, ref: catalog.InstanceRef, step_multiplier: float = 4.0) -> RobotouilleEnv:
    """Our engine on one catalog instance of the data folder ``root`` (its
    ``generated_environment_json``), with the training kitchen as its demonstration; raises
    DataFileError for a malformed instance file."""
    path = instance_path(root, ref.split, ref.task, ref.layout_seed)
    raw = read_json(path)
    problem = require(raw, "generated_environment_json", path)
    if not isinstance(problem, dict):
        raise DataFileError(f"Robotouille data file {str(path)!r}: generated_environment_json is not an object")
    return RobotouilleEnv(
        domain=load_domain(root),
        problem_json=problem,
        source=str(path),
        instance_id=ref.instance_id,
        split=ref.split,
        task=ref.task,
        layout_seed=ref.layout_seed,
        optimal_steps=ref.optimal_steps,
        step_multiplier=step_multiplier,
        demonstration=lambda: demonstration(root),
    )


def make_demo_env(root: Path) -> RobotouilleEnv:
    """Our engine on the training kitchen of the one-shot demonstration."""
    path = train_instance_path(root, DEMO_SPLIT, DEMO_TASK, DEMO_SEED)
    raw = read_json(path)
    problem = require(raw, "generated_environment_json", path)
    return RobotouilleEnv(
        domain=load_domain(root),
        problem_json=problem,
        source=str(path),
        instance_id=f"robotouille/{DEMO_SPLIT}_train/{DEMO_TASK}@{DEMO_SEED}",
        split=DEMO_SPLIT,
        task=DEMO_TASK,
        layout_seed=DEMO_SEED,
        optimal_steps=None,
        max_steps=DEMO_MAX_STEPS,
    )


def demonstration(root: Path) -> Demonstration:
    """The onion cheese sandwich demo (used for sync and async instances alike, as in the paper)."""
    return make_demonstration(lambda: make_demo_env(root))


BENCHMARK = RobotouilleBenchmark()
