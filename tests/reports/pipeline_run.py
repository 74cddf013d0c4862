"""A run folder written by the pipeline itself, for the report tests: ``recap run`` on a local Ray
with the offline test double.

The sweep: ReCAP, ReAct and ReCAP's ``no_think`` ablation (labelled ``recap-no-think``) on
Robotouille synchronous and asynchronous and ALFWorld (one game of two task types), one seed,
two workers, ``max_attempts: 1``. A run cap binds (some units end ``budget_exhausted``, the rest
are never started) and the worker of the first unit dispatched is killed with SIGKILL as soon as
it starts, so the driver gives that unit up (``infra_error``, worker_lost). Nothing in the tests
that use it is hand-written: expected values are recomputed from the run's own Parquet rows.
"""

from __future__ import annotations

import os
import signal
from pathlib import Path
from typing import Any

SWEEP = """run: report-fixture
output: {out}
models:
  - model: offline/expert
    label: expert
    options: {{seed: 7, invalid_action_rate: 0.1, malformed_json_rate: 0.05}}
methods:
  - method: recap
  - method: react
  - method: recap
    label: recap-no-think
    ablation: no_think
environments:
  - benchmark: robotouille
    tasks: [synchronous/0, asynchronous/0]
    limit: 1
  - benchmark: alfworld
    tasks: [heat, put]
    limit: 1
seeds: [0]
workers: 2
max_attempts: 1
run_cap_usd: {cap}
"""
#: binds: the full sweep costs about $4 at the test double's nominal prices
RUN_CAP_USD = 1.2


def run_sweep(folder: Path) -> tuple[Path, int, dict[str, Any]]:
    """Write the sweep file, run ``recap run`` on it with one worker killed, and return the
    run folder, the exit status and what was killed (``unit``: its unit id)."""
    import ray

    import pipeline.driver as driver_mod
    from pipeline.cli import main

    out = folder / "run"
    spec = folder / "sweep.yaml"
    spec.write_text(SWEEP.format(out=out, cap=RUN_CAP_USD))
    killed: dict[str, Any] = {}
    plain_hooks = driver_mod.Hooks

    def kill_first(unit: Any, attempt: int, actor: Any) -> None:
        """Kill the worker that just got the first unit, before the unit can finish."""
        if killed:
            return
        killed["unit"] = unit.unit_id
        pid = ray.get(actor.pid.remote())
        os.kill(pid, signal.SIGKILL)

    class KillingHooks(plain_hooks):  # type: ignore[misc,valid-type]
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            self.on_dispatch = kill_first

    driver_mod.Hooks = KillingHooks
    try:
        code = main(["run", str(spec), "--progress", "off"])
    finally:
        driver_mod.Hooks = plain_hooks
    return out, code, killed
