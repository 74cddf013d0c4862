"""What the SWE-bench harness runs to evaluate a prediction, for an instance whose record it knows.

The harness (swebench 4.x, ``swebench/harness/run_evaluation.py`` ``run_instance``) evaluates a
prediction in a container of the instance's image: it writes the diff to a file and applies it in
``/testbed`` with the first of ``GIT_APPLY_CMDS`` that succeeds (``git apply --verbose``, the same
with ``--reject``, ``patch --batch --fuzz=5 -p1 -i``; nothing is undone between tries), then runs
``/bin/bash /eval.sh``, where ``eval.sh`` is ``make_test_spec(record).eval_script``: conda's
activation, the repository's ``eval_commands``, the test files put back at the base commit and the
test patch applied, then the repository's test command (``MAP_REPO_VERSION_TO_SPECS[repo][version]
["test_cmd"]``) on the test directives of the test patch (Django's as module labels, ``tests/``
and ``.py`` dropped) between the ``START_TEST_OUTPUT`` / ``END_TEST_OUTPUT`` markers. Its parser
reads what lies between the markers.

Our evaluator (:mod:`.evaluate`) runs the same for a SWE-bench Verified instance, in its own clean
sandbox of the same image: the patch applied by :func:`apply_commands`, the script of
:func:`eval_script`; its output is read between the markers (``test_log.harness_test_section``).
Why not run the per-repository test command on the FAIL_TO_PASS ids: Django's
``runtests.py`` takes module labels, not ``test_x (mod.Class)`` ids, and SymPy's ``bin/test`` takes
no pytest ids either, so such a run grades every Django and SymPy instance unresolved.

The script is built with the harness's own ``make_eval_script_list`` (what ``make_test_spec``
calls for ``eval_script_list``) rather than ``make_test_spec`` itself: the latter also builds the
environment script, which fetches requirements files from GitHub for most repositories (a network
call, and offline an error) although the evaluation never runs it. ``swebench`` is imported here
only, lazily (``pip install 'recap-eval[swe]'``).
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from typing import Any

#: the conda environment and the repository folder ``make_test_spec`` uses (test_spec.py)
ENV_NAME = "testbed"
REPO_DIRECTORY = "/testbed"


class HarnessScriptError(ValueError):
    """The harness knows no test command for the record's repository and version (one line)."""


def eval_script(record: Mapping[str, Any]) -> str:
    """``make_test_spec(record).eval_script`` without its environment script (module docstring):
    the harness's ``make_eval_script_list`` for the record, framed by ``TestSpec.eval_script``.
    HarnessScriptError (one line) when the harness has no specs for the repository and version;
    ImportError without ``swebench``."""
    from swebench.harness.constants import MAP_REPO_TO_EXT, MAP_REPO_VERSION_TO_SPECS
    from swebench.harness.test_spec.create_scripts import make_eval_script_list
    from swebench.harness.test_spec.test_spec import TestSpec

    rec = dict(record)
    repo, version = str(rec.get("repo", "")), str(rec.get("version", ""))
    specs = MAP_REPO_VERSION_TO_SPECS.get(repo, {}).get(version)
    if specs is None or repo not in MAP_REPO_TO_EXT:
        raise HarnessScriptError(f"the SWE-bench harness has no eval script for {repo} version {version}")
    rec["version"] = version
    lines = make_eval_script_list(rec, specs, ENV_NAME, REPO_DIRECTORY, rec["base_commit"], rec["test_patch"])
    values: dict[str, Any] = {
        "instance_id": rec.get("instance_id", ""),
        "repo": repo,
        "version": version,
        "repo_script_list": [],
        "eval_script_list": lines,
        "env_script_list": [],
        "arch": "x86_64",
        "FAIL_TO_PASS": [],
        "PASS_TO_PASS": [],
        "language": MAP_REPO_TO_EXT[repo],
        "docker_specs": {},
        "namespace": None,
    }
    accepted = inspect.signature(TestSpec).parameters
    return str(TestSpec(**{k: v for k, v in values.items() if k in accepted}).eval_script)


def apply_commands() -> tuple[str, ...]:
    """The harness's patch commands in its order (``run_evaluation.GIT_APPLY_CMDS``), each taking the patch file."""
    from swebench.harness.run_evaluation import GIT_APPLY_CMDS

    return tuple(str(c) for c in GIT_APPLY_CMDS)
