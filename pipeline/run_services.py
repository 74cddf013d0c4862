"""The run-wide actors benchmarks declare (``Benchmark.run_services``), started by the driver for a Ray run.

Why here: a limit that must hold across every episode worker of a run (FEVER's per-host Wikipedia
politeness) lives in one named actor per run, started like the gateway's actors (restarted by Ray,
pinned to the driver's node) and named to the episode workers through their ``runtime_env``
(the service's ``env_var``). A sweep whose benchmarks declare none starts nothing; the in-process
executor needs none (its one process shares its state already).
"""

from __future__ import annotations

import importlib
import uuid
from typing import Any

from pipeline.gateway_backend import TASK_RETRIES
from pipeline.raysetup import actor_runtime_env
from pipeline.spec import SweepSpec
from workers.envs.registry import RunService, get_benchmark


def declared_services(spec: SweepSpec) -> list[RunService]:
    """The services the sweep's benchmarks declare, each once, in the order of the environments."""
    found: dict[str, RunService] = {}
    for env in spec.environments:
        for service in get_benchmark(env.benchmark).run_services():
            found.setdefault(service.env_var, service)
    return list(found.values())


class RunServices:
    """The run's service actors: :meth:`worker_runtime_env` names them to the episode workers."""

    def __init__(self, started: list[tuple[RunService, str, Any]]) -> None:
        #: (service, actor name, actor handle), in start order
        self.started = started

    @classmethod
    def start(cls, spec: SweepSpec, run_id: str, node_id: str | None) -> RunServices:
        """One actor per declared service, named per run (none when no benchmark declares one)."""
        services = declared_services(spec)
        if not services:
            return cls([])
        # lazy: Ray loads only where a session uses it
        from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

        opts: dict[str, Any] = {"max_restarts": -1, "max_task_retries": TASK_RETRIES}
        if node_id is not None:
            opts["scheduling_strategy"] = NodeAffinitySchedulingStrategy(node_id=node_id, soft=False)
        started = []
        for service in services:
            module, _, attr = service.actor.partition(":")
            actor_cls: Any = getattr(importlib.import_module(module), attr)  # a Ray actor class (stubs lack .options)
            name = f"recap-{service.name}-{run_id}-{uuid.uuid4().hex[:8]}"
            started.append((service, name, actor_cls.options(name=name, **opts).remote()))
        return cls(started)

    def names(self) -> dict[str, str]:
        """Each started service's variable -> its actor's name."""
        return {service.env_var: name for service, name, _ in self.started}

    def worker_runtime_env(self) -> dict[str, Any] | None:
        """The episode workers' ``runtime_env``: the job's variables and the started actors' names
        (:func:`pipeline.raysetup.actor_runtime_env`: None when nothing was started and the local
        cluster's workers have the variables already)."""
        if not self.started:
            return actor_runtime_env()
        return actor_runtime_env(self.names())

    def close(self) -> None:
        """End the actors (the run is over; a later session starts its own)."""
        import ray  # lazy: Ray loads only where a session uses it

        for _, _, actor in self.started:
            try:
                ray.kill(actor)
            except Exception:
                pass
