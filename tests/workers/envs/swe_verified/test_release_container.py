"""``container: harness | release``: the two set-ups the paper's SWE-bench numbers came from.

The release's environment is read from the authors' files (``../shared/data/recap-release``) where
a test states it; the offline tests play an episode with a local sandbox standing in for both
containers and a local git repository as the clone source (``repo_mirror``); the Docker test runs
one in a stand-in base image built from the project's sandbox image.
"""

from __future__ import annotations

import json
import re
import secrets
import subprocess
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from workers.envs.registry import get_benchmark, make_env
from workers.envs.swe.examples import TEST_CMD
from workers.envs.swe.rules import NETWORK_OFF, NETWORK_ON
from workers.envs.swe_verified import images
from workers.envs.swe_verified.env import VerifiedEnvironment
from workers.envs.swe_verified.release_container import (
    RELEASE_ENV,
    RELEASE_IMAGE,
    ReleaseEnvironment,
    default_container,
    fetch_at,
)
from workers.sandbox import SandboxSpec, open_sandbox

from .conftest import built_image, write_jsonl

RELEASE = Path(__file__).resolve().parents[4].parent / "shared" / "data" / "recap-release" / "swebench-recap"
SPECS = {"fixture/offbyone": {"0.1": {"test_cmd": TEST_CMD}}}


def _git(repo: Path, *args: str) -> str:
    return subprocess.run(["git", *args], cwd=repo, capture_output=True, text=True, check=True).stdout.strip()


@pytest.fixture
def stored(records, tmp_path, cache, monkeypatch) -> dict[str, str]:
    """The first fixture record stored as the dataset, the harness's test command table knowing it."""
    rec = records[0]
    from pipeline.cli import main

    assert (
        main(["data", "fetch", "swebench-verified", "--from", str(write_jsonl(tmp_path / "one.jsonl", [rec])), "--subset"]) == 0
    )
    monkeypatch.setattr("workers.envs.swe_verified.harness._specs", lambda: SPECS)
    return rec


@pytest.fixture
def mirror(verified_fixtures, stored, tmp_path) -> Path:
    """A mirror folder: ``fixture__offbyone`` cloned from the fixture repository, with one more
    commit after the base commit (which the release's fetch of the base commit must not bring)."""
    folder = tmp_path / "mirror"
    repo = folder / "fixture__offbyone"
    src = verified_fixtures.tasks_file.parent / "repos" / "offbyone"
    subprocess.run(["git", "clone", "-q", str(src), str(repo)], check=True)
    (repo / "LATER.txt").write_text("a commit after the base commit\n")
    _git(repo, "add", "-A")
    _git(repo, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "-m", "later")
    return folder


def _play_expert(env: Any) -> tuple[list[str], Any]:
    calls, step = [], None
    for _ in range(30):
        plan = env.expert_plan()
        assert plan
        call = json.loads(plan[0])
        step = env.call_tool(call["name"], call["arguments"])
        calls.append(call["name"])
        if step.done:
            break
    return calls, step


# -- the release's set-up, as its files say ---------------------------------------------------------------


def test_the_release_ran_in_swe_agents_default_container() -> None:
    """What release mode reproduces is what the release's files give SWE-agent: the run script passes
    only the repository's GitHub URL and base commit; recap.yaml has no ``env`` section, so the
    deployment is SWE-agent's default image; the repository is a depth-1 fetch into /<owner>__<name>."""
    run = (RELEASE / "run_swe_bench_tasks.py").read_text()
    assert re.findall(r'"--env\.[^"=]+', run) == ['"--env.repo.github_url', '"--env.repo.base_commit']
    assert "https://github.com/{repo_string}" in run
    config = (RELEASE / "config" / "recap.yaml").read_text()
    assert not re.search(r"^env:", config, re.M)
    swe_env = (RELEASE / "sweagent" / "environment" / "swe_env.py").read_text().splitlines()
    assert f'image="{RELEASE_IMAGE}"' in swe_env[27]
    assert all(f'"{k}": "{v}"' in swe_env[188] for k, v in list(RELEASE_ENV.items())[:4])
    tools_env = config.split("env_variables:", 1)[1].split("bundles:", 1)[0]
    assert {k: str(v) for k, v in __import__("yaml").safe_load(tools_env).items()} == dict(list(RELEASE_ENV.items())[2:])
    repo = (RELEASE / "sweagent" / "environment" / "repo.py").read_text().splitlines()
    assert 'f"git fetch --depth 1 origin {base_commit}",' in repo[171] and 'return f"{org}__{repo}"' in repo[145]


# -- options ------------------------------------------------------------------------------------------------


def test_each_method_defaults_to_the_set_up_of_its_paper_number() -> None:
    bench = get_benchmark("swe-verified")
    assert [bench.options_for_agent(s) for s in ("recap", "mini_swe", "react")] == [
        {"container": "release"},
        {"container": "harness"},
        {"container": "harness"},
    ]
    assert default_container("recap") == "release"
    from recap.methods import make_agent

    released = make_agent("mini_swe", profile="released", benchmark=bench).config
    paper = make_agent("mini_swe", profile="paper", benchmark=bench).config
    # mini-swe-agent 1.0.0 started the harness's image with Docker's default network
    assert bench.options_for_agent("mini_swe", released) == {"container": "harness", "network": True}
    assert bench.options_for_agent("mini_swe", paper) == {"container": "harness"}
    # ReCAP as swebench-recap ran it: SWE-agent's tool limits (sweagent/tools/tools.py:139-150)
    recap_released = make_agent("recap", profile="released", benchmark=bench).config
    recap_paper = make_agent("recap", profile="paper", benchmark=bench).config
    assert bench.options_for_agent("recap", recap_released) == {
        "container": "release",
        "command_timeout_s": 30.0,
        "wall_time_s": 1800.0,
        "max_timeouts_in_row": 3,
    }
    assert bench.options_for_agent("recap", recap_paper) == {"container": "release"}


def test_max_timeouts_in_row_reaches_the_verified_environment(stored) -> None:
    """The release's ``max_consecutive_execution_timeouts`` (``max_timeouts_in_row``) is a
    swe-verified option (it was refused as unknown) and reaches the environment."""
    env = make_env(f"swe-verified/{stored['instance_id']}", open_sandbox=print, max_timeouts_in_row=3)
    assert env.max_timeouts_in_row == 3
    with pytest.raises(ValueError, match=r"^max_timeouts_in_row must be a positive integer, got 0$"):
        make_env(f"swe-verified/{stored['instance_id']}", open_sandbox=print, max_timeouts_in_row=0)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"container": "docker"}, "container must be one of harness, release, got 'docker'"),
        (
            {"container": "release", "release_image": "python 3.11"},
            "release_image must be a Docker image name, got 'python 3.11'",
        ),
        ({"repo_mirror": "/nonexistent/mirror"}, "repo_mirror /nonexistent/mirror is not a folder"),
    ],
)
def test_bad_container_options_are_one_line(stored, options, message) -> None:
    bench = get_benchmark("swe-verified")
    refusal = bench.preflight([f"swe-verified/{stored['instance_id']}"], options)
    assert refusal is not None and refusal.startswith(message) and "\n" not in refusal
    with pytest.raises(ValueError, match=re.escape(message)):
        make_env(f"swe-verified/{stored['instance_id']}", open_sandbox=lambda spec: None, **options)


def test_a_mirror_without_the_repository_is_refused(stored, tmp_path) -> None:
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match=r"^repo_mirror .*empty has no git repository fixture__offbyone for fixture/offbyone$"):
        make_env(
            f"swe-verified/{stored['instance_id']}", container="release", repo_mirror=str(tmp_path / "empty"), open_sandbox=print
        )


def test_preflight_refuses_a_missing_release_image_in_one_line(stored, monkeypatch) -> None:
    iid = f"swe-verified/{stored['instance_id']}"
    harness_image = images.remote_image(stored["instance_id"])
    monkeypatch.setattr("workers.envs.swe_verified.benchmark.local_images", lambda: {harness_image})
    bench = get_benchmark("swe-verified")
    assert bench.preflight([iid], {}) is None  # harness: its image is here
    assert bench.preflight([iid], {"container": "release"}) == (
        "container release runs in the image python:3.11, which is not here; `docker pull python:3.11` "
        "where a registry is reachable, or set release_image to a local image"
    )
    monkeypatch.setattr("workers.envs.swe_verified.benchmark.local_images", lambda: {harness_image, "python:3.11"})
    assert bench.preflight([iid], {"container": "release"}) is None


def test_fetch_at_leaves_the_base_commit_alone(mirror, stored, tmp_path) -> None:
    dest = tmp_path / "clone"
    fetch_at(str(mirror / "fixture__offbyone"), stored["base_commit"], dest)
    assert _git(dest, "rev-parse", "HEAD") == stored["base_commit"]
    assert _git(dest, "rev-list", "--all", "--count") == "1"
    assert not (dest / "LATER.txt").exists()
    from workers.sandbox.base import SandboxError

    with pytest.raises(SandboxError, match=r"^git fetch of 0{40} from .* failed: ") as info:
        fetch_at(str(mirror / "fixture__offbyone"), "0" * 40, tmp_path / "bad", remote=False)
    assert info.value.service is False  # a mirror without the commit fails the same way again
    with pytest.raises(SandboxError) as info:
        fetch_at(str(mirror / "fixture__offbyone"), "0" * 40, tmp_path / "bad2")
    assert info.value.service is True  # GitHub: the network may come back (infra_error, resumed)


# -- an episode ---------------------------------------------------------------------------------------------


def test_a_release_episode_runs_at_the_base_commit_and_its_diff_is_graded_in_the_harness_spec(
    verified_fixtures, stored, mirror
) -> None:
    """Offline: a local sandbox stands in for both containers. The episode's spec is the release's
    (image, /<owner>__<name>, its variables, network on); its repository is the base commit alone;
    the expert's diff is graded in the harness's spec (the image holds the repository: repo_path None,
    /testbed), resolved."""
    opened: list[SandboxSpec] = []
    fixture_repo = verified_fixtures.tasks_file.parent / "repos" / "offbyone"

    def opener(spec: SandboxSpec):
        opened.append(spec)
        if spec.repo_path is None:  # the harness image's stand-in: the fixture repository at the base commit
            spec = replace(spec, repo_path=str(fixture_repo), env={})  # (no conda here)
        return open_sandbox("local", spec)

    iid = f"swe-verified/{stored['instance_id']}"
    # grading both: our evaluator in the (stand-in) harness spec; the harness's own run needs Docker
    env = make_env(iid, container="release", repo_mirror=str(mirror), open_sandbox=opener, command_timeout_s=30, grading="both")
    assert isinstance(env, ReleaseEnvironment)
    try:
        assert env.workdir == "/fixture__offbyone"
        env.reset()
        assert NETWORK_ON in env.rules() and NETWORK_OFF not in env.rules()  # the release's container has it
        episode = opened[0]
        assert (episode.image, episode.workdir, dict(episode.env), episode.limits.network) == (
            RELEASE_IMAGE,
            "/fixture__offbyone",
            dict(RELEASE_ENV),
            True,
        )
        assert episode.repo_path is not None and not Path(episode.repo_path).exists()  # fetched, copied in, removed
        box = env._box()
        assert box.workdir.endswith("/fixture__offbyone")
        assert box.run("git rev-parse HEAD && git rev-list --all --count && git status --porcelain").output.split() == [
            stored["base_commit"],
            "1",
        ]
        calls, step = _play_expert(env)
        assert calls == ["view", "str_replace", "bash", "submit", "submit"]
        assert step.done and step.success and step.info["resolved"] is True
        assert step.info["patch"] == stored["patch"]
        evaluation = opened[1]
        assert (evaluation.repo_path, evaluation.workdir, evaluation.image) == (None, images.TESTBED, "")
    finally:
        env.close()


def test_harness_stays_the_default_of_make(stored) -> None:
    env = make_env(f"swe-verified/{stored['instance_id']}", open_sandbox=print)
    assert isinstance(env, VerifiedEnvironment) and not isinstance(env, ReleaseEnvironment)
    assert env.workdir == images.TESTBED
    assert env.limits.network is False and NETWORK_OFF in env.rules()


# -- Docker -------------------------------------------------------------------------------------------------


@pytest.fixture
def docker_images(docker_ready: str, verified_fixtures, stored) -> Iterator[tuple[str, str]]:
    """A stand-in for ``python:3.11``: the project's sandbox image (Debian's Python 3.11 and git, no
    repository) under another tag; and the instance's harness image (the fixture repository at
    /testbed). Both removed afterwards (the stand-in's tag only)."""
    from workers.sandbox.docker_sandbox import docker_client

    repository, tag = "recap-eval-test/release-base", secrets.token_hex(4)
    client = docker_client()
    client.images.get(docker_ready).tag(repository, tag)
    harness = images.local_image(stored["instance_id"])
    try:
        with built_image(docker_ready, verified_fixtures.tasks_file.parent / "repos" / "offbyone", harness):
            yield f"{repository}:{tag}", harness
    finally:
        client.images.remove(f"{repository}:{tag}")


@pytest.mark.docker
def test_an_episode_runs_in_the_release_container_at_the_base_commit_and_is_graded(docker_images, stored, mirror) -> None:
    base, harness = docker_images
    iid = f"swe-verified/{stored['instance_id']}"
    bench = get_benchmark("swe-verified")
    options = {"container": "release", "release_image": base, "repo_mirror": str(mirror)}
    assert bench.preflight([iid], options) is None
    assert "which is not here" in str(bench.preflight([iid], {**options, "release_image": base + "-missing"}))
    # grading both: the fixture's repository is no SWE-bench repository, which the harness's own run needs
    env = make_env(iid, command_timeout_s=30, grading="both", **options)
    try:
        env.reset()
        box = env._box()  # type: ignore[attr-defined]
        assert box.workdir == "/fixture__offbyone"
        assert box.run("git rev-parse HEAD").output.strip() == stored["base_commit"]
        assert box.run("git rev-list --all --count").output.strip() == "1"  # the base commit alone
        assert box.run("echo $TQDM_DISABLE $GIT_PAGER").output.strip() == "1 cat"
        assert box.run("test -e /testbed").exit_code == 1  # not the harness's image
        inspect = subprocess.run(
            ["docker", "inspect", "-f", "{{.Config.Image}} {{.HostConfig.NetworkMode}}", box.container_id],
            capture_output=True,
            text=True,
            check=True,
        )
        assert inspect.stdout.split() == [base, "bridge"]
        calls, step = _play_expert(env)
        assert calls == ["view", "str_replace", "bash", "submit", "submit"]
        assert step.success and step.info["resolved"] is True and step.info["eval_reason"] == "resolved"
        assert step.info["patch"] == stored["patch"]
    finally:
        env.close()
    # nothing left: no container of either image (by the name it was started with; the stand-in is a
    # tag of the shared sandbox image, whose other containers ``ancestor=`` would also match)
    left = subprocess.run(["docker", "ps", "-a", "--format", "{{.Image}}"], capture_output=True, text=True, check=True)
    assert not {base, harness} & set(left.stdout.split())


# -- the sweep's preflight ------------------------------------------------------------------------------------

SWEEP = """run: containers
output: /tmp/never-written
models:
  - model: offline/expert
methods:
  - method: recap
  - method: mini_swe
environments:
  - benchmark: swe-verified
    tasks: [{iid}]
{options}"""


def _check(stored, options: str = "") -> str | None:
    from pipeline.errors import SpecError
    from pipeline.preflight import check_plan
    from pipeline.spec import parse_spec
    from pipeline.units import expand

    try:
        check_plan(expand(parse_spec(SWEEP.format(iid=stored["instance_id"], options=options), "sweep.yaml")))
    except SpecError as exc:
        return str(exc)
    return None


def test_a_sweep_whose_release_image_is_missing_is_refused_before_it_runs(stored, monkeypatch) -> None:
    """ReCAP's column runs in the release's container by default: its image missing refuses the
    sweep in one line (mini_swe alone runs in the harness's image and needs none)."""
    harness_image = images.remote_image(stored["instance_id"])
    monkeypatch.setattr("workers.envs.swe_verified.benchmark.local_images", lambda: {harness_image})
    message = _check(stored)
    assert message == (
        f"environments[0] (swe-verified): cannot open swe-verified/{stored['instance_id']}: SandboxError: container "
        "release runs in the image python:3.11, which is not here; `docker pull python:3.11` where a registry is "
        "reachable, or set release_image to a local image"
    )
    assert _check(stored, "    options: {container: harness}") is None  # every column in the harness's image
    monkeypatch.setattr("workers.envs.swe_verified.benchmark.local_images", lambda: {harness_image, "python:3.11"})
    assert _check(stored) is None
    assert _check(stored, "    options: {container: docker}") == (
        "environments[0] (swe-verified): container must be one of harness, release, got 'docker'"
    )
