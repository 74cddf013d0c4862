"""The run-wide Wikipedia politeness actor: started by the driver for a sweep with a FEVER environment.

Why here: the per-host limit must hold across every episode worker of a run, so it lives in one
named actor per run (:class:`workers.envs.fever.politeness.WikiPoliteness`), started like the
gateway's actors (restarted by Ray, pinned to the driver's node) and named to the episode workers
through their ``runtime_env`` (:data:`workers.envs.fever.ratelimit.POLITENESS_VAR`). A sweep
without FEVER starts nothing; the in-process executor needs nothing (its one process shares its
bucket already).
"""

from __future__ import annotations

import uuid
from typing import Any

from pipeline.gateway_backend import TASK_RETRIES
from pipeline.raysetup import runtime_env
from pipeline.spec import SweepSpec
from workers.envs.fever.claims import BENCHMARK_NAME
from workers.envs.fever.ratelimit import POLITENESS_VAR


class RunPoliteness:
    """The run's one WikiPoliteness actor: :meth:`worker_runtime_env` names it to the episode workers."""

    def __init__(self, name: str, actor: Any) -> None:
        self.name = name
        self.actor = actor

    @classmethod
    def start(cls, spec: SweepSpec, run_id: str, node_id: str | None) -> RunPoliteness | None:
        """The actor, named per run, when ``spec`` has a FEVER environment; else None (nothing started)."""
        if not any(env.benchmark == BENCHMARK_NAME for env in spec.environments):
            return None
        # lazy: Ray and the actor's module load only where a session uses them
        from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

        from workers.envs.fever.politeness import WikiPoliteness

        opts: dict[str, Any] = {"max_restarts": -1, "max_task_retries": TASK_RETRIES}
        if node_id is not None:
            opts["scheduling_strategy"] = NodeAffinitySchedulingStrategy(node_id=node_id, soft=False)
        name = f"recap-wiki-politeness-{run_id}-{uuid.uuid4().hex[:8]}"
        actor_cls: Any = WikiPoliteness  # Ray's stubs do not know the .options of a decorated class
        return cls(name, actor_cls.options(name=name, **opts).remote())

    def worker_runtime_env(self) -> dict[str, Any]:
        """The episode workers' ``runtime_env``: the job's variables and the actor's name."""
        env_vars = dict(runtime_env()["env_vars"])
        env_vars[POLITENESS_VAR] = self.name
        return {"env_vars": env_vars}

    def close(self) -> None:
        """End the actor (the run is over; a later session starts its own)."""
        import ray  # lazy: Ray loads only where a session uses it

        try:
            ray.kill(self.actor)
        except Exception:
            pass
