"""A SWE-bench Verified episode: the coding environment of ``workers/envs/swe`` in the instance's own image.

What differs from :class:`~workers.envs.swe.env.SweEnvironment` (everything else - tools, limits,
submission, evaluation - is the same class):

* no repository is copied in: the harness's image holds it at ``/testbed`` at the base commit
  (``SandboxSpec.repo_path`` None), with its environment installed; commands see the harness's
  conda environment first on ``PATH`` (its eval script runs ``conda activate testbed``);
* the submission is the diff against the image's own starting state, not the base commit: the
  harness's install step edits some repositories' files in the image (sphinx's ``tox.ini``...),
  and those edits are not the model's; the evaluation's clean copy starts from the same image, so
  the diff applies there;
* the expert reads the base commit's files from the sandbox (there is no repository on the host);
* the evaluation is the harness's under every grading (:meth:`VerifiedEnvironment._evaluate`): its
  eval script, not ``test_cmd -rA <ids>`` (which Django's and SymPy's runners refuse).
"""

from __future__ import annotations

import shlex
import time
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

from recap.env import EnvError, Reset
from workers.envs.swe.env import SweEnvironment
from workers.envs.swe.evaluate import MISSING, Evaluation, evaluate, refused_evaluation
from workers.envs.swe.grading import OfficialGrade, parser_name
from workers.envs.swe.harness_script import HarnessScriptError, eval_script
from workers.sandbox.docker_sandbox import BASE_ENV

from .harness_eval import HARNESS_GRADING, harness_evaluation, harness_run_id, namespace_for, run_harness
from .images import CONDA_BIN, CONDA_ENV_BIN, TESTBED

BENCHMARK_NAME = "swe-verified"
#: where the base commit's copy of a file is written for the expert (inside ``.git``: never in a diff)
BASE_FILE = ".git/recap-eval-base.txt"


class VerifiedEnvironment(SweEnvironment):
    """A SWE-bench Verified instance in its harness image (see the module docstring)."""

    benchmark = BENCHMARK_NAME

    def __init__(self, *args: Any, record: Mapping[str, Any] | None = None, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        #: the dataset record as stored (what ``grading: harness`` hands the harness)
        self.record = dict(record or {})
        self.instance_id = f"{BENCHMARK_NAME}/{self.instance.instance_id}"
        path = f"{CONDA_ENV_BIN}:{CONDA_BIN}:{BASE_ENV['PATH']}"
        self.spec = replace(self.spec, repo_path=None, workdir=TESTBED, env={**self.spec.env, "PATH": path})
        self._start_tree = ""

    def reset(self) -> Reset:
        """The sandbox of the image, and the tree it starts from (what the submission is diffed against)."""
        first = super().reset()
        res = self._box().run("git add -A && git write-tree")
        tree = res.output.strip().splitlines()[-1:] if res.exit_code == 0 else []
        if not tree or len(tree[0]) < 40:
            self.close()
            raise EnvError(f"{self.instance_id}: cannot read the image's repository state: {res.output.strip()[:200]}")
        self._start_tree = tree[0]
        return first

    def current_diff(self) -> str:
        """The changes against the image's starting state, new files included, taken as a user's
        task's are (:meth:`~workers.envs.swe.env.SweEnvironment._diff_against`)."""
        return self._diff_against(self._start_tree)

    def _evaluate(self, diff: str) -> Evaluation:
        """The harness's evaluation of ``diff`` under every grading, bounded by ``eval_timeout_s``:
        ``harness``: the harness's own run_evaluation (:mod:`.harness_eval`); ``ours``, ``official``,
        ``both``: its eval script in our clean copy of the image (:mod:`workers.envs.swe.harness_script`),
        the log graded by the harness's parser and/or ours. An empty diff is judged as in every mode: no patch;
        a diff that writes outside the repository likewise: refused unapplied (``patch_refused``)."""
        if self.grading != HARNESS_GRADING or not diff.strip():
            script = self._eval_script()
            return evaluate(
                self.instance,
                diff,
                self._open_clean,
                grading=self.grading,
                eval_timeout_s=self.eval_timeout_s,
                eval_script=script,
            )
        if (refused := refused_evaluation(self.instance, diff)) is not None:  # never handed to the harness
            official = OfficialGrade(False, None, parser_name(self.instance.repo), dict.fromkeys(refused.tests, MISSING))
            return replace(refused, official=official, grading=HARNESS_GRADING, pass_to_pass=self.instance.pass_to_pass)
        started = time.monotonic()
        run = run_harness(
            self.record,
            diff,
            run_id=harness_run_id(self.spec.labels),
            namespace=namespace_for(self.spec.image),
            timeout_s=self.eval_timeout_s,
        )
        ev = harness_evaluation(self.instance, run)
        return replace(ev, pass_to_pass=self.instance.pass_to_pass, duration_s=time.monotonic() - started)

    def _eval_script(self) -> str | None:
        """The harness's eval script of the record; None (the instance's ``test_cmd -rA <ids>``, as
        for a user's task) where the harness has no specs for its repository and version - which
        :meth:`~.benchmark.VerifiedBenchmark.make` refuses, so only a test's fixture table gets here."""
        if not self.record:
            return None
        try:
            return eval_script(self.record)
        except HarnessScriptError:
            return None

    def _base_text(self, path: str) -> str:
        box = self._box()
        spec = shlex.quote(f"{self.instance.base_commit}:{path}")
        if box.run(f"git show {spec} > {BASE_FILE}").exit_code != 0:
            raise EnvError(f"{self.instance_id}: the gold patch names {path}, which the base commit lacks")
        return box.read_file(BASE_FILE).decode("utf-8", errors="replace")

    def _exists_at_base(self, path: str) -> bool:
        spec = shlex.quote(f"{self.instance.base_commit}:{path}")
        return self._box().run(f"git cat-file -e {spec}").exit_code == 0
