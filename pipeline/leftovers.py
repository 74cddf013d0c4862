"""Removing what episodes left running: the sandboxes of a worker that died, of a killed driver.

Why: a coding episode runs in a container (or a local process sandbox) that its environment
closes when the episode ends. A worker process killed mid-episode never closes it, and a driver
killed with SIGKILL leaves every worker's; a sweep of hundreds of instances would pile them up.
Each benchmark says how to find and remove its own (``Benchmark.remove_leftovers``: the coding
benchmark's sandboxes carry the run's and the worker's labels); the session calls it

* before its workers start: what an earlier session of this run left (a resume after SIGKILL);
* when a worker is lost: that worker's;
* when it ends: anything of the run still there.

A failure to remove is logged and recorded as an event, never a reason to stop the run.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from pipeline.spec import SweepSpec
from workers.envs.registry import get_benchmark

log = logging.getLogger(__name__)


class Leftovers:
    """The run's benchmarks' ``remove_leftovers``, called for the run or one of its workers."""

    def __init__(self, spec: SweepSpec, run_id: str, event: Callable[..., None]) -> None:
        self.run_id = run_id
        self.benchmarks = list(dict.fromkeys(env.benchmark for env in spec.environments))
        self._event = event

    def remove(self, worker_id: str | None = None) -> int:
        """Remove what the run's (or one worker's) environments left; how many things went."""
        removed = 0
        for name in self.benchmarks:
            try:
                removed += get_benchmark(name).remove_leftovers(self.run_id, worker_id)
            except Exception as exc:  # a daemon gone away must not stop the run: say so, go on
                log.warning("could not remove what %s left (worker %s): %s", name, worker_id or "any", exc)
                self._event("leftovers_removed", severity="warning", benchmark=name, worker=worker_id, error=str(exc)[:500])
                continue
        if removed:
            detail: dict[str, Any] = {"removed": removed}
            if worker_id is not None:
                detail["worker"] = worker_id
            self._event("leftovers_removed", **detail)
        return removed
