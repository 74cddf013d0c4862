"""SWE-bench Verified is graded by what the harness runs, under every grading mode.

Before: ``both``/``ours``/``official`` ran ``test_cmd -rA <FAIL_TO_PASS ids>``, which Django's
``runtests.py`` refuses (``-rA``, and ids that are not module labels) and SymPy's ``bin/test``
cannot take, so every Django and SymPy instance - about 60 % of the 500 - was graded unresolved.
Now each mode runs the harness's own eval script (``make_test_spec(record).eval_script``): ours in
our clean sandbox of the instance's image, ``harness`` through ``run_evaluation``. The Docker tests
run it on a Django-shaped and a SymPy-shaped instance (:mod:`.runner_repos`: runners written like
the real ones, records filed under the real repositories), each image built here under the name
the harness gives the published one, with the ``/opt/miniconda3/bin/activate`` its eval script
sources (a shell function standing in for conda, as in :mod:`.test_harness_eval`: the image has
one Python)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path

import pytest

from workers.envs.registry import make_env
from workers.envs.swe.grading import official_grade
from workers.envs.swe.harness_script import HarnessScriptError, apply_commands, eval_script
from workers.envs.swe_verified import images
from workers.envs.swe_verified.benchmark import VERIFIED_DEFAULT_GRADING, as_instance
from workers.envs.swe_verified.env import VerifiedEnvironment

from .conftest import built_image, write_jsonl
from .runner_repos import DJANGO, SHAPES, SYMPY, Built, build

#: the stand-in for conda the harness's eval script sources (the existing fixture image's), and a
#: ``kill`` executable (procps, in every harness image: the harness stops a test run past its
#: timeout with ``exec_run("kill -TERM <pid>")``; the sandbox image has only bash's builtin)
IMAGE_EXTRA = (
    "RUN mkdir -p /opt/miniconda3/bin && printf 'conda() { :; }\\n' > /opt/miniconda3/bin/activate\n"
    "RUN printf '#!/bin/bash\\nkill \"$@\"\\n' > /usr/local/bin/kill && chmod 755 /usr/local/bin/kill\n"
)
MODES = ("both", "ours", "official", "harness")
#: the test run of each eval script, as its trace shows it: the runner on the test patch's directives
RUNS = {
    "django": "./tests/runtests.py --verbosity 2 --settings=test_sqlite --parallel 1 text_utils.tests",
    "sympy": "PYTHONWARNINGS=ignore::UserWarning,ignore::SyntaxWarning\n+ bin/test -C --verbose symini/tests/test_core.py",
}


def test_swe_verified_grades_with_the_harness_by_default() -> None:
    assert VERIFIED_DEFAULT_GRADING == "harness"


def test_the_eval_script_is_the_harness_s_own(tmp_path: Path) -> None:
    """SymPy 1.12's environment needs no network, so ``make_test_spec`` itself can be compared:
    the script is the harness's byte for byte; Django's puts module labels after its test command."""
    from swebench.harness.test_spec.test_spec import make_test_spec

    sympy = build(SYMPY, tmp_path).record
    assert eval_script(sympy) == make_test_spec(dict(sympy)).eval_script
    django = build(DJANGO, tmp_path).record
    script = eval_script(django)
    start = script.index(": '>>>>> Start Test Output'\n")
    assert script[start:].splitlines()[:3] == [
        ": '>>>>> Start Test Output'",
        "./tests/runtests.py --verbosity 2 --settings=test_sqlite --parallel 1 text_utils.tests",
        ": '>>>>> End Test Output'",
    ]
    assert script.splitlines()[2:4] == ["source /opt/miniconda3/bin/activate", "conda activate testbed"]
    assert apply_commands() == ("git apply --verbose", "git apply --verbose --reject", "patch --batch --fuzz=5 -p1 -i")
    with pytest.raises(HarnessScriptError, match=r"^the SWE-bench harness has no eval script for fixture/offbyone version 0.1$"):
        eval_script({**django, "repo": "fixture/offbyone", "version": "0.1"})


def _python_first(tmp_path: Path) -> dict[str, str]:
    """The environment with this interpreter as ``python`` first on PATH (the runners' ``#!/usr/bin/env python``)."""
    bin_dir = tmp_path / "bin"
    if not bin_dir.exists():
        bin_dir.mkdir()
        (bin_dir / "python").symlink_to(sys.executable)
    return {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '')}"}


def _test_run(built: Built, patch: str, tmp_path: Path) -> str:
    """The eval script's test command on a copy of the repository with ``patch`` and the test
    patch applied (no conda here: the command alone, as the script runs it between its markers)."""
    script = eval_script(built.record)
    command = script.split(": '>>>>> Start Test Output'\n")[1].split("\n: '>>>>> End Test Output'")[0]
    work = tmp_path / "work"
    shutil.copytree(built.path, work)
    for p in (patch, built.record["test_patch"]):
        subprocess.run(["git", "apply", "-"], input=p, text=True, cwd=work, check=True)
    done = subprocess.run(["bash", "-c", command], cwd=work, capture_output=True, text=True, env=_python_first(tmp_path))
    shutil.rmtree(work)
    return done.stdout + done.stderr


@pytest.mark.parametrize("shape", ["django", "sympy"])
def test_the_runners_print_what_the_harness_parsers_read(shape: str, tmp_path: Path) -> None:
    """Without Docker: the runners' output, graded by the harness's parser for the repository,
    resolves the gold patch and not the wrong one; the test ids are the parser's."""
    built = build(SHAPES[shape], tmp_path / "repo")
    inst = as_instance(built.record, "unused")
    gold = official_grade(inst, _test_run(built, built.record["patch"], tmp_path), patch_applied=True)
    wrong = official_grade(inst, _test_run(built, built.wrong_patch, tmp_path), patch_applied=True)
    f2p, p2p = SHAPES[shape].fail_to_pass, SHAPES[shape].pass_to_pass
    assert (gold.resolved, gold.parser, dict(gold.tests)) == (True, f"parse_log_{shape}", {t: "PASSED" for t in (*f2p, *p2p)})
    assert (wrong.resolved, wrong.fail_to_pass_failure, wrong.pass_to_pass_success) == (False, f2p, p2p)
    assert wrong.tests[f2p[0]] == "FAILED"


def test_the_django_runner_refuses_pytest_ids(tmp_path: Path) -> None:
    """What ``test_cmd -rA <ids>`` did on Django: the runner refuses it and no test runs."""
    built = build(DJANGO, tmp_path)
    done = subprocess.run(
        [sys.executable, "tests/runtests.py", "--verbosity", "2", "-rA", DJANGO.fail_to_pass[0]],
        cwd=built.path,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 2 and "unrecognized arguments: -rA" in done.stderr


#: one xdist worker for the tests of ``shaped`` (when the slow suite runs under RECAP_TEST_WORKERS): it
#: tags its images under fixed names and removes them when the module ends
SHAPED = pytest.mark.xdist_group("swe_verified_shaped")


@pytest.fixture(scope="module")
def shaped(docker_ready: str, tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Built]]:
    """The two repositories in images under the harness's published names, their records stored
    as the swebench-verified data (in a cache folder of the module's own)."""
    folder = tmp_path_factory.mktemp("shaped")
    built = {name: build(shape, folder / "repos") for name, shape in SHAPES.items()}
    with ExitStack() as stack, pytest.MonkeyPatch.context() as mp:
        for b in built.values():
            stack.enter_context(built_image(docker_ready, b.path, images.remote_image(b.record["instance_id"]), IMAGE_EXTRA))
        mp.setenv("RECAP_EVAL_CACHE", str(folder / "cache"))
        mp.delenv("SWEBENCH_VERIFIED_DATA", raising=False)
        from pipeline.cli import main

        src = write_jsonl(folder / "records.jsonl", [b.record for b in built.values()])
        assert main(["data", "fetch", "swebench-verified", "--from", str(src), "--subset"]) == 0
        yield built


def _env(built: Built, **options: object) -> VerifiedEnvironment:
    env = make_env(f"swe-verified/{built.record['instance_id']}", command_timeout_s=60, **options)
    assert isinstance(env, VerifiedEnvironment)
    return env


@SHAPED
@pytest.mark.docker
@pytest.mark.slow
@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("shape", ["django", "sympy"])
def test_every_grading_resolves_the_gold_patch_and_not_one_that_leaves_the_bug(shaped, shape: str, mode: str) -> None:
    built = shaped[shape]
    f2p, p2p = SHAPES[shape].fail_to_pass, SHAPES[shape].pass_to_pass
    env = _env(built, grading=mode)
    gold = env._evaluate(built.record["patch"])
    assert (gold.success, gold.verdict_reason, gold.grading) == (True, "resolved", mode)
    # our reading of the same log, beside the deciding one (the repository's parser, our criterion)
    assert (gold.resolved, dict(gold.tests)) == (True, {t: "PASSED" for t in (*f2p, *p2p)})
    assert gold.graded_by == ("ours" if mode == "ours" else "official")
    if mode != "ours":
        assert gold.official is not None
        assert (gold.official.status, gold.official.parser) == ("RESOLVED_FULL", f"parse_log_{shape}")
        assert (gold.official.fail_to_pass_success, gold.official.pass_to_pass_success) == (f2p, p2p)
    if mode != "harness":  # our evaluator ran the harness's eval script in our sandbox
        assert f"+ {RUNS[shape]}\n" in gold.log and "+ conda activate testbed" in gold.log  # bash -x's trace
        assert "$ git apply --verbose .git/recap-eval-model.patch  # the model's patch" in gold.log
        assert "-rA" not in gold.log
    wrong = env._evaluate(built.wrong_patch)
    assert (wrong.success, wrong.verdict_reason, wrong.resolved) == (False, "tests_failed", False)
    assert dict(wrong.tests) == {**{t: "FAILED" for t in f2p}, **{t: "PASSED" for t in p2p}}
    if mode != "ours":
        assert wrong.official is not None
        assert (wrong.official.status, wrong.official.fail_to_pass_failure, wrong.official.pass_to_pass_success) == (
            "RESOLVED_NO",
            f2p,
            p2p,
        )
    assert wrong.failing_tests() == list(f2p)


@SHAPED
@pytest.mark.docker
@pytest.mark.slow
def test_an_episode_is_graded_by_the_harness_by_default(shaped) -> None:
    """The expert's episode on the Django-shaped instance, no grading option: the harness decides."""
    built = shaped["django"]
    env = _env(built)
    try:
        env.reset()
        for _ in range(30):
            call = json.loads(env.expert_plan()[0])  # type: ignore[index]
            step = env.call_tool(call["name"], call["arguments"])
            if step.done:
                break
        assert (step.success, step.info["graded_by"], step.info["official_status"]) == (True, "official", "RESOLVED_FULL")
        (record,) = env.take_records("ep-1", "run-1")
        assert (record.resolved, record.grading, record.official_resolved, record.patch) == (
            True,
            "harness",
            True,
            built.record["patch"],
        )
    finally:
        env.close()


HANG = "def sign(x):\n    while True:\n        pass\n"


@SHAPED
@pytest.mark.docker
@pytest.mark.slow
@pytest.mark.parametrize("mode", ["both", "harness"])
def test_eval_timeout_s_bounds_the_test_run(shaped, mode: str, tmp_path: Path) -> None:
    """A patch whose tests never end: ``eval_timeout_s`` (5 s) stops the run, not the instance's
    1800 s, in our sandbox's run of the eval script and in the harness's (its ``--timeout``)."""
    built = shaped["sympy"]
    repo = tmp_path / "r"
    shutil.copytree(built.path, repo)
    (repo / "symini/core.py").write_text(HANG)
    hang = subprocess.run(["git", "diff"], cwd=repo, capture_output=True, text=True, check=True).stdout
    env = _env(built, grading=mode, eval_timeout_s=5)
    started = time.monotonic()
    ev = env._evaluate(hang)
    assert (ev.success, ev.verdict_reason) == (False, "timeout")
    assert time.monotonic() - started < 120


def test_the_harness_run_gets_eval_timeout_s_and_runs_offline_with_a_published_image(tmp_path: Path, monkeypatch) -> None:
    """Without Docker: the harness's ``--timeout`` is the environment's ``eval_timeout_s`` (not the
    instance's 1800 s); with a published image its environment-script fetches are replaced (they
    would reach GitHub), with a local build they are not."""
    from workers.envs.swe_verified import harness_eval

    built = build(DJANGO, tmp_path)
    calls: list[list[str]] = []

    def fake_run(cmd: list[str], **kwargs: object) -> subprocess.CompletedProcess[str]:
        calls.append(cmd)
        return subprocess.CompletedProcess(cmd, 0, "", "")

    monkeypatch.setattr(harness_eval.subprocess, "run", fake_run)
    for image in (images.remote_image(built.record["instance_id"]), images.local_image(built.record["instance_id"])):
        env = VerifiedEnvironment(
            as_instance(built.record, "unused"),
            lambda spec: pytest.fail("the harness grading opens no sandbox of ours"),
            record=built.record,
            grading="harness",
            eval_timeout_s=7.5,
            image=image,
        )
        with pytest.raises(Exception, match="the SWE-bench harness evaluated nothing"):
            env._evaluate(built.record["patch"])  # the fake harness wrote nothing
    (published, local) = calls
    assert published[1:2] == ["-c"] and published[3] == "published" and local[3] == "local"
    assert published[published.index("--timeout") + 1] == "8"  # 7.5 s, rounded up
    assert published[published.index("--namespace") + 1] == "swebench" and local[local.index("--namespace") + 1] == "none"
    assert "specs.get_requirements = " in published[2]
