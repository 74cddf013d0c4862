"""``eval_timeout_s`` binds the evaluation's test run (it was ignored: the instance's own bound ran)."""

from __future__ import annotations

import time
from typing import Any

from tests.workers.envs.swe.sandbox_log import SandboxLog
from workers.envs.registry import make_env
from workers.envs.swe.env import SweEnvironment
from workers.envs.swe.evaluate import TEST_LOG_FILE
from workers.envs.swe.examples import HANG_TIMEOUT_S, Fixtures
from workers.sandbox import Sandbox, SandboxSpec


def _recording(sandboxes: SandboxLog, runs: list[tuple[str, float | None]]) -> Any:
    """``sandboxes``, each sandbox's commands and their ``timeout_s`` noted in ``runs``."""

    def opener(spec: SandboxSpec) -> Sandbox:
        box = sandboxes(spec)
        run = box.run

        def noted(command: str, *, timeout_s: float | None = None) -> Any:
            runs.append((command, timeout_s))
            return run(command, timeout_s=timeout_s)

        box.run = noted  # type: ignore[method-assign]
        return box

    return opener


def test_the_option_bounds_the_test_run_not_the_instance_s_timeout(fixtures: Fixtures, sandboxes: SandboxLog) -> None:
    """The ``hang`` task's wrong patch loops forever; its own bound is HANG_TIMEOUT_S (10 s), the
    option's 2 s: the run is stopped after 2 s."""
    runs: list[tuple[str, float | None]] = []
    env = make_env(
        "swe/fixture__hang-1",
        instances_file=str(fixtures.tasks_file),
        open_sandbox=_recording(sandboxes, runs),
        eval_timeout_s=2,
        grading="ours",
    )
    assert isinstance(env, SweEnvironment) and env.instance.eval_timeout_s == HANG_TIMEOUT_S
    started = time.monotonic()
    ev = env._evaluate(fixtures.wrong_patches["hang"])
    took = time.monotonic() - started
    assert (ev.success, ev.verdict_reason) == (False, "timeout")
    (test_run,) = [(c, t) for c, t in runs if c.endswith(f"> {TEST_LOG_FILE} 2>&1")]
    assert test_run[1] == 2.0
    assert took < HANG_TIMEOUT_S
    assert sandboxes.specs[-1].limits.command_timeout_s >= 2.0
