"""``grading: harness``: the swebench package's own ``run_evaluation`` judges the submission.

The Docker tests build an image as the harness names a published one (``swebench/sweb.eval...``)
for a fixture task filed under a repository the harness knows (``pytest-dev/pytest`` 7.0: its
specs give the eval script, its parser reads pytest's ``-rA`` lines): the fixture repository at
``/testbed`` and the ``/opt/miniconda3/bin/activate`` the harness's eval script sources (a shell
function standing in for conda: the image has one Python). Everything else - the container, the
patch, the eval script, the log parser, report.json - is the installed harness's own code."""

from __future__ import annotations

import json
import secrets
import subprocess
from collections.abc import Iterator

import pytest

from workers.envs.registry import make_env
from workers.envs.swe.instances import SweInstance
from workers.envs.swe_verified import images
from workers.envs.swe_verified.harness_eval import (
    HarnessRun,
    eval_test_output,
    harness_evaluation,
    harness_run_id,
    namespace_for,
    run_harness,
)
from workers.sandbox.base import SandboxError

from .conftest import built_image, write_jsonl

F2P, P2P = "tests/test_mathutil.py::test_count_range_inclusive", "tests/test_mathutil.py::test_total"


def _instance() -> SweInstance:
    return SweInstance(
        instance_id="fixture__offbyone-1",
        repo="pytest-dev/pytest",
        base_commit="0" * 40,
        problem_statement="",
        fail_to_pass=(F2P,),
        pass_to_pass=(P2P,),
        patch="",
        test_patch="",
        repo_path="",
        test_cmd="pytest -rA",
    )


LOG = f"""+ : '>>>>> Start Test Output'
PASSED {P2P}
FAILED {F2P} - assert [1, 2] == [1, 2, 3]
+ : '>>>>> End Test Output'
"""


def test_the_harness_report_decides_and_our_reading_of_its_log_sits_beside_it() -> None:
    report = {
        "resolved": False,
        "tests_status": {"FAIL_TO_PASS": {"success": [], "failure": [F2P]}, "PASS_TO_PASS": {"success": [P2P], "failure": []}},
    }
    ev = harness_evaluation(_instance(), HarnessRun(report, LOG, "instance log", 0, ""))
    assert eval_test_output(LOG) == f"'\nPASSED {P2P}\nFAILED {F2P} - assert [1, 2] == [1, 2, 3]\n+ : '"
    assert (ev.success, ev.graded_by, ev.verdict_reason, ev.grading, ev.log) == (
        False,
        "official",
        "tests_failed",
        "harness",
        "instance log",
    )
    assert ev.tests == {F2P: "FAILED", P2P: "PASSED"}  # ours, from the same log
    assert ev.official is not None and ev.official.status == "RESOLVED_NO"
    assert (ev.official.fail_to_pass_failure, ev.official.pass_to_pass_success, ev.official.parser) == (
        (F2P,),
        (P2P,),
        "parse_log_pytest",
    )


def test_without_a_report_the_harness_log_says_why_and_a_harness_that_ran_nothing_is_the_service() -> None:
    applied = harness_evaluation(_instance(), HarnessRun(None, "", "x\n>>>>> Patch Apply Failed:\nerror: patch failed\n", 0, ""))
    assert (applied.success, applied.verdict_reason) == (False, "patch_failed")
    slow = harness_evaluation(_instance(), HarnessRun(None, "", "Test timed out after 60 seconds.\n", 0, ""))
    assert slow.verdict_reason == "timeout"
    with pytest.raises(
        SandboxError, match=r"^the SWE-bench harness evaluated nothing \(exit 1\): docker.errors.DockerException: gone$"
    ) as err:
        harness_evaluation(_instance(), HarnessRun(None, "", "", 1, "Traceback\ndocker.errors.DockerException: gone\n"))
    assert err.value.service


def test_the_namespace_follows_the_image_found_here() -> None:
    assert namespace_for(images.remote_image("django__django-1")) == "swebench"
    assert namespace_for(images.local_image("django__django-1")) == "none"


def test_harness_grading_is_swe_verified_only(tmp_path) -> None:
    from workers.envs.swe.examples import make_fixtures

    fx = make_fixtures(tmp_path / "fx", ("offbyone",))
    with pytest.raises(ValueError, match=r"^grading must be one of ours, official, both, got 'harness'$"):
        make_env("swe/fixture__offbyone-1", instances_file=str(fx.tasks_file), grading="harness")


@pytest.fixture
def harness_image(docker_ready: str, verified_fixtures, records) -> Iterator[tuple[str, dict[str, str]]]:
    """A record filed under ``pytest-dev/pytest`` 7.0 with a unique id, and its image under the published name."""
    rec = {**records[0], "instance_id": f"pytest-dev__pytest-{secrets.randbelow(10**9) + 10**9}"}
    rec.update(repo="pytest-dev/pytest", version="7.0")
    name = images.remote_image(rec["instance_id"])
    conda = (
        "ENV PYTHONPATH=/testbed\nRUN mkdir -p /opt/miniconda3/bin && printf 'conda() { :; }\\n' > /opt/miniconda3/bin/activate\n"
    )
    with built_image(docker_ready, verified_fixtures.tasks_file.parent / "repos" / "offbyone", name, conda):
        yield name, rec


@pytest.mark.docker
def test_an_episode_graded_by_the_harness_is_resolved_by_its_report(harness_image, tmp_path, cache) -> None:
    name, rec = harness_image
    from pipeline.cli import main

    assert (
        main(["data", "fetch", "swebench-verified", "--from", str(write_jsonl(tmp_path / "one.jsonl", [rec])), "--subset"]) == 0
    )
    env = make_env(f"swe-verified/{rec['instance_id']}", command_timeout_s=30, grading="harness")
    try:
        env.reset()
        for _ in range(30):
            call = json.loads(env.expert_plan()[0])  # type: ignore[attr-defined]
            step = env.call_tool(call["name"], call["arguments"])
            if step.done:
                break
        assert (step.success, step.info["graded_by"], step.info["eval_reason"], step.info["official_status"]) == (
            True,
            "official",
            "resolved",
            "RESOLVED_FULL",
        )
        (record,) = env.take_records("ep-1", "run-1")
        assert (record.resolved, record.grading, record.graded_by, record.ours_resolved, record.official_resolved) == (
            True,
            "harness",
            "official",
            True,
            True,
        )
        assert (record.fail_to_pass_passed, record.pass_to_pass_passed, record.patch) == (1, 1, rec["patch"])
        assert "Result for " in record.log and "resolved: True" in record.log  # the harness's own instance log
    finally:
        env.close()
    # a patch that applies but leaves the bug: the harness runs the tests and reports the failure
    notes = (
        "diff --git a/notes.txt b/notes.txt\nnew file mode 100644\n--- /dev/null\n+++ b/notes.txt\n@@ -0,0 +1 @@\n+not fixed\n"
    )
    run = run_harness(rec, notes, run_id="recap-test-" + secrets.token_hex(4), namespace="swebench", timeout_s=120)
    assert run.report is not None and run.report["resolved"] is False
    assert run.report["tests_status"]["FAIL_TO_PASS"] == {"success": [], "failure": [F2P]}
    assert run.report["tests_status"]["PASS_TO_PASS"] == {"success": [P2P], "failure": []}
    ev = harness_evaluation(_instance(), run)
    assert (ev.success, ev.verdict_reason, ev.resolved, ev.tests) == (
        False,
        "tests_failed",
        False,
        {F2P: "FAILED", P2P: "PASSED"},
    )
    leftover = subprocess.run(["docker", "ps", "-aq", "--filter", f"ancestor={name}"], capture_output=True, text=True)
    assert leftover.stdout.strip() == ""


def test_the_harness_run_id_carries_the_run_and_the_worker() -> None:
    from workers.sandbox import LABEL_RUN, LABEL_WORKER

    rid = harness_run_id({LABEL_RUN: "Run_2026-11-26T0500abcdef", LABEL_WORKER: "w-3"})
    assert rid.startswith("recap-run20261126t-w3-") and len(rid) == len("recap-run20261126t-w3-") + 8


@pytest.mark.docker
def test_resume_removes_the_harness_containers_a_killed_worker_left(docker_ready: str) -> None:
    """A worker killed while the harness evaluated leaves the harness's container (named by it,
    not labelled by us); the benchmark's leftover removal finds it by that name - the run's only."""
    from workers.envs.registry import get_benchmark
    from workers.sandbox import LABEL_RUN, LABEL_WORKER

    run = "run" + secrets.token_hex(4)
    ours = f"sweb.eval.django__django-1.{harness_run_id({LABEL_RUN: run, LABEL_WORKER: 'w1'})}"
    other = f"sweb.eval.django__django-1.{harness_run_id({LABEL_RUN: 'another' + run, LABEL_WORKER: 'w1'})}"
    for name in (ours, other):
        subprocess.run(
            ["docker", "run", "-d", "--network", "none", "--name", name, docker_ready, "sleep", "600"],
            check=True,
            capture_output=True,
        )
    try:
        bench = get_benchmark("swe-verified")
        assert bench.remove_leftovers(run, "w2") == 0  # another worker's: kept
        assert bench.remove_leftovers(run) == 1
        names = subprocess.run(["docker", "ps", "-a", "--format", "{{.Names}}"], capture_output=True, text=True).stdout.split()
        assert ours not in names and other in names
    finally:
        subprocess.run(["docker", "rm", "-f", ours, other], capture_output=True)
