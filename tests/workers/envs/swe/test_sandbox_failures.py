"""A sandbox that fails under an episode: when the container service failed (the daemon, a
container gone) the episode's error starts with ``sandbox:`` and the pipeline reads the row as
infrastructure (``infra_error``, run again by resume); when the sandbox fails for the instance or
for what the agent did, it stays an ``env_error`` outcome. Played through the agent's runtime on
the fixture tasks with real local sandboxes, one of which is made to fail."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from recap.methods import make_agent
from recap.runtime import EnvDriver, EpisodeEnd
from schemas.labels import infra_failure
from workers.envs.registry import get_benchmark, make_env
from workers.envs.swe.env import SweEnvironment
from workers.envs.swe.examples import Fixtures
from workers.episode_worker import EpisodeClient
from workers.llm.direct import LiteLLMClient
from workers.llm.providers import DeploymentConfig
from workers.sandbox import Sandbox, SandboxError, SandboxSpec, open_sandbox
from workers.sandbox.base import SandboxUnavailable


class _FailsAfter:
    """A local sandbox whose commands fail with ``error`` after ``after`` of them ran."""

    def __init__(self, box: Sandbox, after: int, error: SandboxError) -> None:
        self.box, self.after, self.error, self.runs = box, after, error, 0

    def __getattr__(self, name: str) -> Any:
        return getattr(self.box, name)

    def __enter__(self) -> _FailsAfter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.box.close()

    def run(self, command: str, **kw: Any) -> Any:
        self.runs += 1
        if self.runs > self.after:
            raise self.error
        return self.box.run(command, **kw)


class _ReadsFail(_FailsAfter):
    """Its file reads fail once ``after`` commands ran; its commands never do (the failure meets
    whatever reads first)."""

    def run(self, command: str, **kw: Any) -> Any:
        self.runs += 1
        return self.box.run(command, **kw)

    def read_file(self, path: str, **kw: Any) -> Any:
        if self.runs >= self.after:
            raise self.error
        return self.box.read_file(path, **kw)


def _opener(
    after: int, error: SandboxError, opened: list[Any], fail_open: bool = False, reads: bool = False
) -> Callable[[SandboxSpec], Any]:
    def open_(spec: SandboxSpec) -> Any:
        if fail_open:
            raise error
        box = (_ReadsFail if reads else _FailsAfter)(open_sandbox("local", spec), after, error)
        opened.append(box)
        return box

    return open_


def _play(fixtures: Fixtures, opener: Callable[[SandboxSpec], Any], method: str = "recap") -> Any:
    env = make_env("swe/fixture__format-1", instances_file=str(fixtures.tasks_file), open_sandbox=opener)
    assert isinstance(env, SweEnvironment)
    agent = make_agent(method, profile="paper", benchmark=get_benchmark("swe"))
    try:
        # the offline expert through litellm, with the expert plan of the current state as a worker adds it
        client = EpisodeClient(LiteLLMClient(DeploymentConfig(model="offline/expert")), env, sampling_seed=0, offline=True)
        return agent.run(env, client, episode_id="ep", demonstration=False)
    finally:
        env.close()


RUNS = {"recap": [2], "react": [2]}


@pytest.mark.parametrize("method", ["recap", "react"])
def test_a_container_that_is_gone_mid_episode_is_infrastructure(fixtures: Fixtures, method: str) -> None:
    opened: list[Any] = []
    gone = SandboxError("the sandbox container is gone", service=True)
    result = _play(fixtures, _opener(1, gone, opened), method)
    assert (result.end_reason, result.error) == (
        "env_error",
        "sandbox: swe/fixture__format-1: the sandbox failed: the sandbox container is gone",
    )
    assert [b.runs for b in opened] == RUNS[method]  # one command ran, the second met the failure
    assert infra_failure(result.end_reason, result.error) == "sandbox"
    assert infra_failure("infra_error", result.error) == "sandbox"  # the row as the pipeline writes it


def test_a_daemon_that_cannot_open_the_sandbox_at_reset_is_infrastructure(fixtures: Fixtures) -> None:
    down = SandboxError("the Docker daemon is unreachable (connection refused); start it", service=True)
    result = _play(fixtures, _opener(0, down, [], fail_open=True))
    assert result.error == (
        "sandbox: reset failed: swe/fixture__format-1: the sandbox cannot be opened: "
        "the Docker daemon is unreachable (connection refused); start it"
    )
    assert infra_failure(result.end_reason, result.error) == "sandbox"


def test_a_sandbox_that_fails_for_the_instance_or_the_agent_is_an_outcome(fixtures: Fixtures) -> None:
    # an image at the wrong commit would fail the same way on every try: not infrastructure
    wrong = SandboxError("/testbed in the image x is at 1234, not at base_commit abcd")
    result = _play(fixtures, _opener(0, wrong, [], fail_open=True))
    assert result.error == "reset failed: swe/fixture__format-1: the sandbox cannot be opened: " + str(wrong)
    assert infra_failure(result.end_reason, result.error) is None
    # a repository the agent broke (git cannot diff it) is the agent's outcome
    broken = SandboxError("git diff failed in the sandbox: fatal: not a git repository")
    result = _play(fixtures, _opener(3, broken, []))
    assert (result.end_reason, infra_failure(result.end_reason, result.error)) == ("env_error", None)
    assert (
        result.error == "swe/fixture__format-1: the sandbox failed: git diff failed in the sandbox: fatal: not a git repository"
    )


@pytest.mark.parametrize(
    ("end_reason", "error", "kind"),
    [
        ("env_error", "sandbox: x: the sandbox failed: gone", "sandbox"),
        ("env_error", "SandboxError: the sandbox container is gone", None),  # rows written before the kind: outcomes
        ("env_error", "x: the sandbox failed: sandbox: gone", None),  # the kind is the first word only
        ("infra_error", "sandbox: x", "sandbox"),
        ("wiki_error", "sandbox: x", None),
    ],
)
def test_only_an_error_that_starts_with_the_sandbox_kind_is_infrastructure(end_reason: str, error: str, kind: str | None) -> None:
    assert infra_failure(end_reason, error) == kind


GONE_ROW = "sandbox: swe/fixture__format-1: the sandbox failed: the sandbox container is gone"


def test_the_expert_plan_reading_a_gone_container_is_the_sandbox_failing(fixtures: Fixtures) -> None:
    """The plan a test-double model reads is made from the sandbox's files: a container gone
    under it is the service failing (as under a tool call), not a raw error out of the agent."""
    gone = SandboxError("the sandbox container is gone", service=True)
    env = make_env(
        "swe/fixture__format-1", instances_file=str(fixtures.tasks_file), open_sandbox=_opener(0, gone, [], reads=True)
    )
    try:
        env.reset()
        with pytest.raises(SandboxUnavailable) as err:
            env.expert_plan()
    finally:
        env.close()
    assert err.value.row_error() == GONE_ROW


def test_a_container_gone_when_a_limit_ends_the_episode_is_the_sandbox_failing(fixtures: Fixtures) -> None:
    """Reaching the command limit hands in the diff from the sandbox (submit_at_limit); a
    container gone then is the service failing, read as infrastructure like any tool call's, and
    through the runtime the episode ends with that failure's row error (kind first)."""
    gone = SandboxError("the sandbox container is gone", service=True)
    env = make_env(
        "swe/fixture__format-1", instances_file=str(fixtures.tasks_file), max_commands=1, open_sandbox=_opener(1, gone, [])
    )
    try:
        env.reset()
        step = env.call_tool("bash", {"command": "true"})  # the one command runs and ends the episode
        assert (step.done, step.info["end_reason"]) == (True, "step_cap")
        with pytest.raises(SandboxUnavailable) as err:
            env.submit_at_limit("step_cap: 1 steps (cap 1)")  # taking its diff meets the failure
        end = EnvDriver(env, "ep", lambda _r: None).submit_at_limit(EpisodeEnd("step_cap", "1 steps (cap 1)"))
    finally:
        env.close()
    assert err.value.row_error() == GONE_ROW
    assert (end.reason, end.detail) == (
        "env_error",
        "sandbox: handing in the work at step_cap: 1 steps (cap 1): swe/fixture__format-1: the sandbox failed: "
        "the sandbox container is gone",
    )
    assert infra_failure(end.reason, end.detail) == "sandbox"


def test_a_worker_whose_expert_plan_meets_a_gone_container_writes_an_infrastructure_row(
    fixtures: Fixtures, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Through the episode worker: the attempt ends with a result whose error carries the kind
    (the row the pipeline reads as ``infra_error`` and resume runs again), not an agent crash
    (which the driver retried at once, writing no row for it)."""
    from schemas.outcomes import UnitWork
    from workers.envs import registry
    from workers.episode_worker import EpisodeRunner

    gone = SandboxError("the sandbox container is gone", service=True)
    real_make_env = registry.make_env
    monkeypatch.setattr(
        registry,
        "make_env",
        lambda instance_id, **kw: real_make_env(
            instance_id, **kw, instances_file=str(fixtures.tasks_file), open_sandbox=_opener(0, gone, [], reads=True)
        ),
    )

    class Expert:
        writes_llm_calls = False

        def client(self, model: str) -> Any:
            return LiteLLMClient(DeploymentConfig(model="offline/expert"))

    config = make_agent("recap", profile="paper", benchmark=get_benchmark("swe")).config.to_json()
    unit = UnitWork(
        "u1", "swe/fixture__format-1", "recap", config, "expert", "offline/expert", sampling_seed=0, step_multiplier=1.0
    )
    out = EpisodeRunner("w1", "run1", Expert(), send=lambda rows: None, wait=lambda ref: None).run_unit(unit, 1)
    assert out.crash is None
    assert out.result is not None and (out.result.end_reason, out.result.error) == ("env_error", GONE_ROW)
    assert infra_failure("infra_error", out.result.error) == "sandbox"


@pytest.mark.parametrize("method", ["recap", "react"])
def test_the_runtime_ends_an_episode_whose_model_call_meets_the_sandbox_failing(fixtures: Fixtures, method: str) -> None:
    """The agent's runtime ends the episode through its one end-of-episode path (as for a step's
    failure): a result with the failure's kind first, its calls counted as sent (none here)."""
    gone = SandboxError("the sandbox container is gone", service=True)
    result = _play(fixtures, _opener(0, gone, [], reads=True), method)
    assert (result.end_reason, result.error, result.llm_calls, result.steps) == ("env_error", GONE_ROW, 0, 0)
