"""One swe-verified episode in a harness-named image that holds the repository at /testbed, played to ``resolved``."""

from __future__ import annotations

import json
import secrets
import subprocess
from collections.abc import Iterator

import pytest

from workers.envs.registry import make_env
from workers.envs.swe.examples import TEST_CMD
from workers.envs.swe_verified import images

from .conftest import built_image, write_jsonl


@pytest.fixture
def instance_image(docker_ready: str, verified_fixtures, records, tmp_path) -> Iterator[tuple[str, dict[str, str]]]:
    """A record with a unique id and its image, named as the harness names a local build:
    ``FROM`` the sandbox image, the fixture repository at ``/testbed`` at the base commit. Removed afterwards."""
    number = str(secrets.randbelow(10**9) + 10**9)
    rec = {**records[0], "instance_id": f"fixture__offbyone-{number}"}
    name = images.local_image(rec["instance_id"])
    with built_image(docker_ready, verified_fixtures.tasks_file.parent / "repos" / "offbyone", name):
        yield name, rec


@pytest.mark.docker
def test_expert_resolves_in_the_instance_image(instance_image, tmp_path, cache, monkeypatch) -> None:
    name, rec = instance_image
    src = write_jsonl(tmp_path / "one.jsonl", [rec])
    from pipeline.cli import main

    assert main(["data", "fetch", "swebench-verified", "--from", str(src), "--subset"]) == 0
    # the harness's table knows no fixture repository: the test command is the example tasks'
    monkeypatch.setattr("workers.envs.swe_verified.harness._specs", lambda: {"fixture/offbyone": {"0.1": {"test_cmd": TEST_CMD}}})
    from workers.envs.registry import get_benchmark

    bench = get_benchmark("swe-verified")
    iid = f"swe-verified/{rec['instance_id']}"
    assert bench.preflight([iid], {}) is None
    env = make_env(iid, command_timeout_s=30)
    try:
        first = env.reset()
        assert first.observation == rec["problem_statement"]
        assert env.workdir == "/testbed"
        head = env._box().run("git rev-parse HEAD && git status --porcelain")  # type: ignore[attr-defined]
        assert head.output.split() == [rec["base_commit"]]
        calls = []
        for _ in range(30):
            plan = env.expert_plan()  # type: ignore[attr-defined]
            assert plan
            call = json.loads(plan[0])
            step = env.call_tool(call["name"], call["arguments"])
            calls.append(call["name"])
            if step.done:
                break
        assert calls == ["view", "str_replace", "bash", "submit", "submit"]
        assert step.success and step.info["resolved"] is True and step.info["eval_reason"] == "resolved"
        assert step.info["patch"] == rec["patch"]
        assert env.instance_id == iid
    finally:
        env.close()
    leftover = subprocess.run(["docker", "ps", "-aq", "--filter", f"ancestor={name}"], capture_output=True, text=True)
    assert leftover.stdout.strip() == ""


@pytest.mark.docker
def test_an_image_at_another_commit_is_refused(instance_image, tmp_path, cache, monkeypatch) -> None:
    name, rec = instance_image
    other = {**rec, "base_commit": "0" * 40}
    src = write_jsonl(tmp_path / "one.jsonl", [other])
    from pipeline.cli import main

    assert main(["data", "fetch", "swebench-verified", "--from", str(src), "--subset"]) == 0
    monkeypatch.setattr("workers.envs.swe_verified.harness._specs", lambda: {"fixture/offbyone": {"0.1": {"test_cmd": TEST_CMD}}})
    env = make_env(f"swe-verified/{rec['instance_id']}")
    from recap.env import EnvError

    with pytest.raises(EnvError) as exc:
        env.reset()
    assert str(exc.value).endswith(f"/testbed in the image {name} is at {rec['base_commit']}, not at base_commit {'0' * 40}")
    env.close()
