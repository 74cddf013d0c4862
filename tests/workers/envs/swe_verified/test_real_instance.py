"""One real SWE-bench Verified instance (``sympy__sympy-23262``) end to end, in an image laid out as
the harness lays its images out (:mod:`.real_instance`): /testbed at the base commit plus the
harness's ``SWE-bench`` commit, the harness's conda activation, its eval script and log parser.

Under every grading mode an episode playing the gold patch is resolved, one submitting a change
that leaves the bug (a comment added to the file the gold patch fixes) is not - the test patch's
FAIL_TO_PASS test fails, every PASS_TO_PASS test passes -, and an empty submission is not. The
record is the real one and the repository at its base commit is read from a git repository
holding it, both shared test data (``../shared/data/swebench-verified-repos``, or
``$RECAP_SWE_REAL_RECORD`` / ``$RECAP_SWE_REAL_REPO``; see ``real_instance.md``): without them the
test says where to put them and is skipped. A last test runs the instance
through `recap run` (ReCAP with the offline expert, the default grading).
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Iterator
from pathlib import Path

import pytest

from workers.envs.registry import make_env
from workers.envs.swe_verified import images

from . import real_instance as R
from .conftest import write_jsonl

#: one xdist worker for the whole module (scripts/test.sh runs the Docker tests in two processes):
#: its image is tagged under the harness's name while the module runs and untagged after it, so a
#: second worker's copy of the module would untag it under the first one's tests. The group is the
#: one of the other Docker tests on Ray (tests/conftest.py): its last test runs a sweep
pytestmark = pytest.mark.xdist_group("docker_ray")

MODES = ("both", "ours", "official", "harness")
#: the change that leaves the bug: a comment line before the function the gold patch fixes
NOT_A_FIX = (
    "sed -i 's/^def _recursive_to_string(doprint, arg):/# not a fix\\n&/' sympy/utilities/lambdify.py"
    " && grep -c '^# not a fix' sympy/utilities/lambdify.py"
)


def _without_index_lines(diff: str) -> str:
    return "".join(line for line in diff.splitlines(True) if not line.startswith("index "))


@pytest.fixture(scope="module")
def real_image(docker_ready: str, tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, dict[str, str]]]:
    """The instance's image (built once per machine, cached by its content hash) tagged under the
    harness's published name while the module runs, and the record."""
    from workers.sandbox.docker_sandbox import docker_client

    record = R.load_record()
    if record is None:
        pytest.skip(f"the record {R.record_file()} is absent: set {R.RECORD_ENV} or put it there (real_instance.md)")
    source = R.repository_source(record["base_commit"])
    if source is None:
        pytest.skip(
            f"no git repository holding {record['repo']}@{record['base_commit'][:12]}: set {R.SOURCE_ENV} to one "
            f"(any clone of https://github.com/{record['repo']}) or put it at {R.DEFAULT_SOURCE}"
        )
    cache = Path(os.environ.get("RECAP_EVAL_CACHE") or Path.home() / ".cache" / "recap-eval") / "test-wheels"
    tag, _ = R.build(docker_ready, source, tmp_path_factory.mktemp("real-image"), cache)
    client = docker_client()
    name = images.remote_image(record["instance_id"])
    ours = client.images.get(tag)
    try:
        there = client.images.get(name)
    except Exception:  # none under that name: ours takes it
        there = None
    if there is not None and there.id != ours.id:
        pytest.fail(f"{name} here is another image (a pulled harness image?): remove it or run this test elsewhere")
    ours.tag(name)
    try:
        yield name, record
    finally:
        client.images.remove(name)  # the name only: the image stays cached under its hash tag


def _play(env, plan_first: list[dict] | None = None) -> tuple:
    """Play ``plan_first`` (tool calls), then the expert's plan when ``plan_first`` is None,
    else submit; the last step and the calls made."""
    calls: list[str] = []
    queue = list(plan_first or [])
    for _ in range(30):
        if plan_first is None:
            call = json.loads(env.expert_plan()[0])
        else:
            call = queue.pop(0) if queue else {"name": "submit", "arguments": {}}
        step = env.call_tool(call["name"], call["arguments"])
        calls.append(call["name"])
        if step.done:
            return step, calls
    raise AssertionError(f"the episode did not end: {calls}")


@pytest.mark.docker
@pytest.mark.parametrize("grading", MODES)
def test_the_gold_patch_is_resolved_and_no_fix_or_an_empty_patch_is_not(real_image, grading, tmp_path, cache) -> None:
    name, rec = real_image
    from pipeline.cli import main

    assert (
        main(["data", "fetch", "swebench-verified", "--from", str(write_jsonl(tmp_path / "one.jsonl", [rec])), "--subset"]) == 0
    )
    f2p, p2p = json.loads(rec["FAIL_TO_PASS"]), json.loads(rec["PASS_TO_PASS"])
    env = make_env(f"swe-verified/{rec['instance_id']}", command_timeout_s=120, grading=grading)
    try:
        # the gold patch, played by the expert through the tools
        first = env.reset()
        assert first.observation == rec["problem_statement"]
        top = env._box().run("git log -1 --format=%s%n%P HEAD && git status --porcelain")  # type: ignore[attr-defined]
        assert top.output.split("\n")[:2] == ["SWE-bench", rec["base_commit"]]  # the harness's layout, taken
        step, calls = _play(env)
        assert calls == ["view", "str_replace", "bash", "submit", "submit"]
        assert (step.success, step.info["eval_reason"]) == (True, "resolved"), step.info
        (gold,) = env.take_records("ep-gold", "run-1")
        assert (gold.resolved, gold.reason, gold.grading) == (True, "resolved", grading)
        assert _without_index_lines(gold.patch) == rec["patch"]
        assert (gold.fail_to_pass_passed, gold.fail_to_pass_total) == (len(f2p), len(f2p))
        assert (gold.pass_to_pass_passed, gold.pass_to_pass_total) == (len(p2p), len(p2p))
        if grading != "ours":
            assert (gold.official_resolved, gold.official_status) == (True, "RESOLVED_FULL")

        # a change that leaves the bug: the tests run, FAIL_TO_PASS fails, PASS_TO_PASS passes
        env.reset()
        step, _ = _play(env, [{"name": "bash", "arguments": {"command": NOT_A_FIX}}])
        assert (step.success, step.info["eval_reason"]) == (False, "tests_failed"), step.info
        (nofix,) = env.take_records("ep-nofix", "run-1")
        assert re.fullmatch(
            r"diff --git a/sympy/utilities/lambdify\.py b/sympy/utilities/lambdify\.py\n(.|\n)*\+# not a fix\n(.|\n)*",
            nofix.patch,
        )
        assert (nofix.resolved, nofix.grading) == (False, grading)
        assert (nofix.fail_to_pass_passed, nofix.pass_to_pass_passed) == (0, len(p2p))
        assert json.loads(nofix.tests)[f2p[0]] == "FAILED"
        if grading != "ours":
            assert (nofix.official_resolved, nofix.official_status) == (False, "RESOLVED_NO")

        # an empty submission
        env.reset()
        step, calls = _play(env, [])
        assert (step.success, step.info["eval_reason"], calls) == (False, "no_patch", ["submit", "submit"])
        (empty,) = env.take_records("ep-empty", "run-1")
        assert (empty.resolved, empty.reason, empty.patch) == (False, "no_patch", "")
    finally:
        env.close()


SWEEP = """run: real-instance
output: {out}
models:
  - model: offline/expert
methods:
  - method: recap
    profile: paper
environments:
  - benchmark: swe-verified
    tasks: [all]
    options: {{container: harness, command_timeout_s: 120, data_dir: "{data}"}}
"""


@pytest.mark.docker
def test_recap_run_resolves_the_instance_with_the_gold_patch(real_image, ray_address, tmp_path, cache) -> None:
    """The whole path: ``recap run`` (its preflight finds the image by the harness's name) plays the
    gold patch with ReCAP and the offline expert in the harness's image (``container: harness``;
    ReCAP's own default is the release's python:3.11 container); the row is graded by the default
    grading."""
    from pipeline.cli import main
    from pipeline.sqlview import open_tables
    from pipeline.store import RunStore

    name, rec = real_image
    assert (
        main(["data", "fetch", "swebench-verified", "--from", str(write_jsonl(tmp_path / "one.jsonl", [rec])), "--subset"]) == 0
    )
    out = tmp_path / "out"
    (tmp_path / "sweep.yaml").write_text(SWEEP.format(out=out, data=cache))  # the workers' folder
    assert main(["run", str(tmp_path / "sweep.yaml"), "--address", ray_address, "--progress", "off"]) == 0
    con, bad = open_tables(RunStore(out))
    assert bad == []
    rows = con.execute(
        "select p.instance_id, p.end_reason, p.success, e.instance_id, e.resolved, e.reason, e.grading, e.graded_by,"
        " e.fail_to_pass_passed, e.pass_to_pass_passed from episodes p join evaluations e using (episode_id)"
    ).fetchall()
    iid, p2p = rec["instance_id"], len(json.loads(rec["PASS_TO_PASS"]))
    # (the evaluations table names an instance as the coding environment does: swe/<id>)
    assert rows == [(f"swe-verified/{iid}", "success", True, f"swe/{iid}", True, "resolved", "harness", "official", 1, p2p)]
