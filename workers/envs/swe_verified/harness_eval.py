"""``grading: harness`` (swe-verified's default): the SWE-bench harness's own full Docker evaluation of a submission.

The other gradings (``both``, ``ours``, ``official``) run the harness's eval script in a clean copy
of the episode's image with our evaluator (:mod:`workers.envs.swe.harness_script`) and grade that
log with the harness's functions (:mod:`workers.envs.swe.grading`) and/or ours. This mode hands
the diff to the harness itself, as a leaderboard submission is evaluated: the ``swebench``
package's ``swebench.harness.run_evaluation`` (:data:`_RUN_EVALUATION`) on a one-line predictions
file and a one-record dataset file (the stored record, so no hub is needed), which starts the
instance's container from its image (the published ``swebench/...`` image when that is what is
here - ``--namespace swebench`` -, else the one the harness built - ``--namespace none``, its own
specs building whatever is missing), applies the patch with its own fallbacks, runs its eval
script (the test patch, the repository's test command), parses the log with the repository's
parser and writes ``report.json``. What it wrote is read back: the report decides ``resolved``;
the eval script's output (``test_output.txt``) is also read by our reader (the harness's parser
for the repository, :func:`~workers.envs.swe.evaluate.read_tests`), so the two
verdicts sit side by side as in the other modes; the harness's instance log is the record's log.

Why a subprocess, not ``run_instance`` in this process: the harness writes under a folder fixed
by a module constant relative to its working directory (``logs/run_evaluation/RUN/MODEL/ID``), so
it runs in a temporary folder of its own; the run id is the episode's (a container name the
harness derives from it never collides across concurrent episodes); and a harness that hangs or
crashes is bounded by a timeout and cannot take the episode worker with it.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
import tempfile
import uuid
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from workers.envs.swe.evaluate import MISSING, EvalReason, Evaluation, ours_resolved, read_tests, with_log
from workers.envs.swe.grading import Grading, OfficialGrade, parser_name
from workers.envs.swe.instances import SweInstance
from workers.envs.swe.test_log import harness_test_section
from workers.sandbox.base import LABEL_RUN, LABEL_WORKER, SandboxError

from .images import NAMESPACE

HARNESS_GRADING: Grading = "harness"
#: the model name the predictions file carries (the harness's log folder is named after it)
MODEL_NAME = "recap-eval"
#: seconds the harness may take beyond the test timeout (container start, patch, grading)
HARNESS_GRACE_S = 600.0
#: ``python -m swebench.harness.run_evaluation`` as is, but for one thing when the published image
#: is used (its first argument ``published``): ``make_test_spec`` also builds the environment
#: script, fetching requirements.txt / environment.yml from GitHub for most repositories (Django's
#: all), which offline fails before any container starts; with a published image that script is
#: never run (the harness takes the image as it is), so those two fetches return a note instead.
#: With a local build (``--namespace none``) nothing is replaced: the harness names the
#: environment image it needs by a hash of that script.
_RUN_EVALUATION = """
import runpy, sys, warnings
warnings.filterwarnings("ignore", message=".*found in sys.modules.*", category=RuntimeWarning)
if sys.argv.pop(1) == "published":
    from swebench.harness.test_spec import python as specs
    note = "# recap-eval: not fetched; the published instance image holds the environment"
    specs.get_requirements = lambda instance: note
    specs.get_environment_yml = lambda instance, env_name: note
sys.argv[0] = "run_evaluation"
runpy.run_module("swebench.harness.run_evaluation", run_name="__main__", alter_sys=True)
"""
#: what the harness logs when the patch does not apply or the tests time out
#: (swebench.harness.constants, run_evaluation.py)
_APPLY_FAIL, _TIMED_OUT = ">>>>> Patch Apply Failed", "Test timed out after"


@dataclass(frozen=True)
class HarnessRun:
    """What one ``run_evaluation`` wrote: its report entry for the instance (None when it wrote
    none: the patch did not apply, the tests timed out, the harness failed), the eval script's
    output, its instance log and how the process ended."""

    report: Mapping[str, Any] | None
    test_output: str
    instance_log: str
    returncode: int
    output: str


def harness_run_id(labels: Mapping[str, str]) -> str:
    """The harness run id of one evaluation: ``recap-<run>-<worker>-<random>`` from the sandbox
    labels (12 characters of each). The harness names its container ``sweb.eval.<id>.<run id>``,
    so a container a killed worker's evaluation left is found by name on resume
    (:func:`remove_harness_containers`), as the episode's own are by label."""
    run, worker = _short(labels.get(LABEL_RUN, "")), _short(labels.get(LABEL_WORKER, ""))
    return f"recap-{run}-{worker}-{uuid.uuid4().hex[:8]}"


def _short(value: str) -> str:
    return (re.sub(r"[^a-z0-9]+", "", value.lower()) or "x")[:12]


def remove_harness_containers(run_id: str, worker_id: str | None = None) -> int:
    """Remove the harness containers of the run's evaluations (or one worker's); the number
    removed. Nothing without a reachable daemon (no container of ours can run then)."""
    import docker
    import docker.errors

    prefix = f"recap-{_short(run_id)}-" + (f"{_short(worker_id)}-" if worker_id is not None else "")
    pattern = re.compile(r"^sweb\.eval\..+\." + re.escape(prefix))
    try:
        found = docker.from_env().containers.list(all=True, filters={"name": prefix})
    except docker.errors.DockerException:
        return 0
    n = 0
    for c in found:
        if pattern.match(c.name or ""):
            try:
                c.remove(force=True)
                n += 1
            except docker.errors.NotFound:
                pass
    return n


def namespace_for(image: str) -> str:
    """The harness's ``--namespace`` for the image found here: ``swebench`` for the published
    name, ``none`` for the harness's own local build."""
    return NAMESPACE if image.startswith(f"{NAMESPACE}/") else "none"


def run_harness(record: Mapping[str, Any], patch: str, *, run_id: str, namespace: str, timeout_s: float) -> HarnessRun:
    """``run_evaluation`` for one instance and one patch in a temporary folder (module docstring),
    its ``--timeout`` (the eval script's bound inside the harness) ``timeout_s``, the episode's
    ``eval_timeout_s``; the process itself is bounded by ``timeout_s`` + :data:`HARNESS_GRACE_S`.
    RuntimeError (one line) when the process cannot be started or runs past its bound."""
    iid = str(record["instance_id"])
    with tempfile.TemporaryDirectory(prefix="recap-eval-harness-") as tmp:
        folder = Path(tmp)
        (folder / "instance.json").write_text(json.dumps([dict(record)]))
        pred = {"instance_id": iid, "model_name_or_path": MODEL_NAME, "model_patch": patch}
        (folder / "predictions.jsonl").write_text(json.dumps(pred) + "\n")
        cmd = [
            sys.executable,
            "-c",
            _RUN_EVALUATION,
            "published" if namespace != "none" else "local",
            "--dataset_name",
            str(folder / "instance.json"),
            "--split",
            "test",
            "--instance_ids",
            iid,
            "--predictions_path",
            str(folder / "predictions.jsonl"),
            "--max_workers",
            "1",
            "--run_id",
            run_id,
            "--timeout",
            str(max(1, math.ceil(timeout_s))),
            "--namespace",
            namespace,
            "--cache_level",
            "instance",  # never remove the instance image it ran in
            "--clean",
            "false",
            "--report_dir",
            str(folder / "reports"),
        ]
        try:
            done = subprocess.run(cmd, cwd=folder, capture_output=True, text=True, timeout=timeout_s + HARNESS_GRACE_S)
        except subprocess.TimeoutExpired:
            raise RuntimeError(f"the SWE-bench harness ran past {timeout_s + HARNESS_GRACE_S:g} s on {iid}") from None
        except OSError as exc:
            raise RuntimeError(f"the SWE-bench harness cannot start: {exc}") from None
        logs = folder / "logs" / "run_evaluation" / run_id / MODEL_NAME / iid
        report_file = logs / "report.json"
        report = json.loads(report_file.read_text()).get(iid) if report_file.exists() else None
        return HarnessRun(
            report=report,
            test_output=_read(logs / "test_output.txt"),
            instance_log=_read(logs / "run_instance.log"),
            returncode=done.returncode,
            output=(done.stdout + done.stderr)[-4000:],
        )


def _read(path: Path) -> str:
    return path.read_text(encoding="utf-8", errors="replace") if path.exists() else ""


def eval_test_output(test_output: str) -> str:
    """The test run's part of the eval script's output, cut as the harness cuts it
    (:func:`~workers.envs.swe.test_log.harness_test_section`: after the start marker, up to the end
    marker; the whole output of a harness 2.x eval script, which printed no markers)."""
    return harness_test_section(test_output)


def harness_evaluation(instance: SweInstance, run: HarnessRun) -> Evaluation:
    """The :class:`Evaluation` of a harness run: the harness's report decides (``official``), our
    reading of the same test output beside it. Without a report: ``patch_failed`` or ``timeout``
    as the harness logged it; a harness that evaluated nothing else (its container could not
    start, the daemon failed) is the sandbox service failing (SandboxError, ``service``)."""
    wanted = (*instance.fail_to_pass, *instance.pass_to_pass)
    section = eval_test_output(run.test_output)
    tests = read_tests(instance, run.test_output) if section else {t: MISSING for t in wanted}
    ours = bool(section) and ours_resolved(instance, tests)
    log = run.instance_log or run.output
    if run.report is None:
        if _APPLY_FAIL in run.instance_log:
            reason: EvalReason = "patch_failed"
        elif _TIMED_OUT in run.instance_log:
            reason = "timeout"
        else:
            last = (run.instance_log or run.output).strip().splitlines()[-1:] or ["no output"]
            raise SandboxError(f"the SWE-bench harness evaluated nothing (exit {run.returncode}): {last[0][:200]}", service=True)
        official = OfficialGrade(False, None, parser_name(instance.repo), {t: MISSING for t in wanted})
        ev = Evaluation(False, reason, tests, official=official, grading=HARNESS_GRADING, test_output=section)
        return with_log(ev, log)
    status = run.report.get("tests_status") or {}
    f2p, p2p = status.get("FAIL_TO_PASS", {}), status.get("PASS_TO_PASS", {})
    passed = {*f2p.get("success", []), *p2p.get("success", [])}
    official = OfficialGrade(
        bool(run.report.get("resolved")),
        _resolution(f2p, p2p),
        parser_name(instance.repo),
        {t: ("PASSED" if t in passed else "FAILED") for t in wanted},
        tuple(f2p.get("success", [])),
        tuple(f2p.get("failure", [])),
        tuple(p2p.get("success", [])),
        tuple(p2p.get("failure", [])),
    )
    ev = Evaluation(
        ours, "resolved" if ours else "tests_failed", tests, official=official, grading=HARNESS_GRADING, test_output=section
    )
    return with_log(ev, log)


def _resolution(f2p: Mapping[str, Any], p2p: Mapping[str, Any]) -> str:
    """The harness's resolution status of a report's test lists (``get_resolution_status``)."""
    from swebench.harness.grading import get_resolution_status  # lazy: an optional dependency

    return str(get_resolution_status({"FAIL_TO_PASS": f2p, "PASS_TO_PASS": p2p}))
