"""One registry of benchmarks, so the CLI and the pipeline address any instance by id.

An instance id is ``<benchmark>/<rest>``, e.g. ``robotouille/asynchronous/5_potato_soup@42`` or
``alfworld/pick_heat_then_place_in_recep/...``. Each benchmark package exposes a ``BENCHMARK``
object with ``list_instances(selector)`` and ``make(instance_id, **options)``; the registry
imports it only when first used, so a missing optional dependency (alfworld) affects only
that benchmark.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from typing import Any, Protocol

from recap.env import DataNotFoundError, Environment, UnknownInstanceError

__all__ = ["DataNotFoundError", "UnknownInstanceError", "Benchmark", "get_benchmark", "make_env", "split_id", "benchmark_names"]


class Benchmark(Protocol):
    name: str

    def list_instances(self, selector: str | None = None) -> list[str]:
        """Instance ids in a fixed order; ``selector`` narrows (split, task, task type...)."""

    def make(self, instance_id: str, **options: Any) -> Environment:
        """A fresh environment for ``instance_id`` (options: step_multiplier, data_dir...)."""


_MODULES: Mapping[str, str] = {
    "blocksworld": "recap.blocksworld",
    "robotouille": "workers.envs.robotouille",
    "alfworld": "workers.envs.alfworld",
}


def benchmark_names() -> list[str]:
    return list(_MODULES)


def get_benchmark(name: str) -> Benchmark:
    try:
        module = _MODULES[name]
    except KeyError:
        raise UnknownInstanceError(
            f"unknown benchmark {name!r}; known: {', '.join(_MODULES)}"
        ) from None
    return importlib.import_module(module).BENCHMARK


def split_id(instance_id: str) -> tuple[str, str]:
    bench, sep, rest = instance_id.partition("/")
    if not sep or not rest:
        raise UnknownInstanceError(
            f"instance id {instance_id!r} must look like <benchmark>/<instance>, "
            f"benchmarks: {', '.join(_MODULES)}"
        )
    return bench, rest


def make_env(instance_id: str, **options: Any) -> Environment:
    bench, _ = split_id(instance_id)
    return get_benchmark(bench).make(instance_id, **options)
