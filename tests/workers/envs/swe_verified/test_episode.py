"""One swe-verified episode in a harness-named image that holds the repository at /testbed, played to ``resolved``
(graded by the harness's eval script run in our clean container)."""

from __future__ import annotations

import json
import secrets
import subprocess
from collections.abc import Iterator

import pytest

from workers.envs.registry import make_env
from workers.envs.swe_verified import images

from .conftest import built_image, write_jsonl

#: the ``/opt/miniconda3/bin/activate`` the harness's eval script sources: a shell function
#: standing in for conda (the image has one Python), as in test_harness_eval.py
CONDA = "ENV PYTHONPATH=/testbed\nRUN mkdir -p /opt/miniconda3/bin && printf 'conda() { :; }\\n' > /opt/miniconda3/bin/activate\n"


@pytest.fixture
def instance_image(docker_ready: str, verified_fixtures, records, tmp_path) -> Iterator[tuple[str, dict[str, str]]]:
    """A record with a unique id and its image, named as the harness names a local build:
    ``FROM`` the sandbox image, the fixture repository at ``/testbed`` at the base commit. Removed afterwards."""
    number = str(secrets.randbelow(10**9) + 10**9)
    rec = {**records[0], "instance_id": f"pytest-dev__pytest-{number}"}
    # filed under a repository the harness knows: its specs give the eval script every grading runs
    rec.update(repo="pytest-dev/pytest", version="7.0")
    name = images.local_image(rec["instance_id"])
    with built_image(docker_ready, verified_fixtures.tasks_file.parent / "repos" / "offbyone", name, CONDA):
        yield name, rec


@pytest.mark.docker
def test_expert_resolves_in_the_instance_image(instance_image, tmp_path, cache) -> None:
    name, rec = instance_image
    src = write_jsonl(tmp_path / "one.jsonl", [rec])
    from pipeline.cli import main

    assert main(["data", "fetch", "swebench-verified", "--from", str(src), "--subset"]) == 0
    from workers.envs.registry import get_benchmark

    bench = get_benchmark("swe-verified")
    iid = f"swe-verified/{rec['instance_id']}"
    assert bench.preflight([iid], {}) is None
    # our evaluator runs the harness's eval script in a clean container of the image (a local
    # build's name: the harness itself would want the environment image it was built from)
    env = make_env(iid, command_timeout_s=30, grading="both")
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
        assert step.info["official_status"] == "RESOLVED_FULL"
        assert step.info["tests"] == {
            "tests/test_mathutil.py::test_count_range_inclusive": "PASSED",
            "tests/test_mathutil.py::test_total": "PASSED",
        }
        (record,) = env.take_records("ep-1", "run-1")
        assert (record.grading, record.graded_by, record.ours_resolved, record.official_resolved) == (
            "both",
            "official",
            True,
            True,
        )
        assert "+ pytest -rA tests/test_mathutil.py\n" in record.log  # the harness's eval script ran
        assert step.info["patch"] == rec["patch"]
        assert env.instance_id == iid
    finally:
        env.close()
    leftover = subprocess.run(["docker", "ps", "-aq", "--filter", f"ancestor={name}"], capture_output=True, text=True)
    assert leftover.stdout.strip() == ""


@pytest.mark.docker
def test_an_image_at_another_commit_is_refused(instance_image, tmp_path, cache) -> None:
    name, rec = instance_image
    other = {**rec, "base_commit": "0" * 40}
    src = write_jsonl(tmp_path / "one.jsonl", [other])
    from pipeline.cli import main

    assert main(["data", "fetch", "swebench-verified", "--from", str(src), "--subset"]) == 0
    env = make_env(f"swe-verified/{rec['instance_id']}")
    from recap.env import EnvError

    with pytest.raises(EnvError) as exc:
        env.reset()
    assert str(exc.value).endswith(f"/testbed in the image {name} is at {rec['base_commit']}, not at base_commit {'0' * 40}")
    env.close()
