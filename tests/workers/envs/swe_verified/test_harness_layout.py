"""An instance image laid out as the SWE-bench harness 4.x lays its images out: /testbed at the base
commit plus the harness's ``SWE-bench`` commit on top (``make_repo_script_list_py``: its install
step, then ``git commit --allow-empty -am SWE-bench``, which also takes what the install changed
in tracked files). Such an image was refused ("/testbed ... is at <that commit>, not at
base_commit") and every episode ended ``env_error`` before its first step.

The fixture repository stands in for the real one (the real SymPy instance is
``test_real_instance.py``, which needs SymPy's repository): here the install edits a tracked file
(as the harness's sed on sphinx's ``tox.ini`` does), and that edit is the image's, not the
model's: the submission is the gold patch alone and applies in the evaluation's clean copy.
"""

from __future__ import annotations

import json
import secrets
from collections.abc import Iterator

import pytest

from workers.envs.registry import make_env
from workers.envs.swe_verified import images
from workers.sandbox.docker_sandbox import HARNESS_COMMIT_SUBJECT

from .conftest import built_image, write_jsonl

#: the harness's setup script's last lines (swebench 4.x harness/test_spec/python.py), after an
#: install that changed a tracked file
HARNESS_SETUP = (
    "ENV PYTHONPATH=/testbed\nRUN mkdir -p /opt/miniconda3/bin && printf 'conda() { :; }\\n' > /opt/miniconda3/bin/activate\n"
    "RUN cd /testbed && printf '*.log\\n' >> .gitignore"
    " && git config --global user.email setup@swebench.config && git config --global user.name SWE-bench"
    f" && git commit --allow-empty -am {HARNESS_COMMIT_SUBJECT}\n"
)


@pytest.fixture
def harness_layout_image(docker_ready: str, verified_fixtures, records) -> Iterator[tuple[str, dict[str, str]]]:
    # filed under a repository the harness knows (its specs give the eval script); the conda stand-in
    # of test_episode.py (the image has one Python)
    rec = {**records[0], "instance_id": f"pytest-dev__pytest-{secrets.randbelow(10**9) + 10**9}"}
    rec.update(repo="pytest-dev/pytest", version="7.0")
    name = images.local_image(rec["instance_id"])
    with built_image(docker_ready, verified_fixtures.tasks_file.parent / "repos" / "offbyone", name, HARNESS_SETUP):
        yield name, rec


@pytest.mark.docker
def test_an_image_with_the_harness_commit_on_the_base_commit_runs_and_resolves(harness_layout_image, tmp_path, cache) -> None:
    name, rec = harness_layout_image
    from pipeline.cli import main

    assert (
        main(["data", "fetch", "swebench-verified", "--from", str(write_jsonl(tmp_path / "one.jsonl", [rec])), "--subset"]) == 0
    )
    # our evaluator runs the harness's eval script in a clean container of the image (a local build's
    # name: the harness itself would want the environment image it was built from)
    env = make_env(f"swe-verified/{rec['instance_id']}", command_timeout_s=30, grading="both")
    try:
        env.reset()
        top = env._box().run("git log -1 --format=%s%n%P HEAD && git diff --name-only HEAD~1 HEAD")  # type: ignore[attr-defined]
        assert top.output.split() == [HARNESS_COMMIT_SUBJECT, rec["base_commit"], ".gitignore"]
        for _ in range(30):
            call = json.loads(env.expert_plan()[0])  # type: ignore[attr-defined]
            step = env.call_tool(call["name"], call["arguments"])
            if step.done:
                break
        assert (step.success, step.info["eval_reason"]) == (True, "resolved"), step.info
        assert step.info["patch"] == rec["patch"]  # the install's .gitignore edit is not in it
    finally:
        env.close()
