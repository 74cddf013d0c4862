"""One SWE-bench task as an environment: a repository in a sandbox, tools to change it, a verdict.

The paper's protocol (section "SWE-bench"; appendix "SWE-bench Verified Experiment Details"): the
model acts through tool calls on a container holding the repository, with no list of valid actions
(any call a tool accepts is valid: ``valid_actions`` is None, ``invalid_action_mode`` ``step``), no
demonstration, and ends by submitting, which reviews first as the release's ``review_on_submit_m``
does (swebench-recap/tools/review_on_submit_m/bin/submit:36-42: the first submit shows the review
message with the diff, the next one submits). The submission is the repository's diff against the
base commit, new files included (bin/submit:24: ``git add -A && git diff --cached``) less the
byte-code and binary blocks no ``git apply`` applies (:mod:`.submission_diff`), judged by
:func:`.evaluate.evaluate` on a clean copy.

Two ways to act:

* tool calls (:meth:`SweEnvironment.call_tool`, the paper's ReCAP): ``bash``, ``view``,
  ``str_replace``, ``create``, ``insert``, ``undo_edit``, ``submit`` (:mod:`.tools`); ``bash`` runs in one session per
  episode (:mod:`workers.sandbox.session`: cd and variables carry over, as in SWE-agent);
* text (:meth:`SweEnvironment.step`, the mini-SWE-agent baseline): the action is one bash command;
  one whose output starts with the line ``COMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT`` submits at once
  (mini-SWE-agent's sentinel, checked by ``DefaultAgent.has_finished`` in minisweagent/agents/default.py;
  no review there).

Per-episode limits (:class:`~workers.sandbox.base.SandboxLimits` ``max_commands`` and
``wall_time_s``, and a total of output bytes) are enforced here: the call that reaches one is
answered, then the episode ends ``step_cap`` (commands) or ``episode_limit``. At that end, and at
every other limit (the model's cost, tokens, calls, context), the runtime asks
:meth:`SweEnvironment.submit_at_limit` to hand in the current diff: a non-empty one is judged and
the episode ends ``autosubmitted`` (SWE-agent's autosubmission, swebench-recap/sweagent/agent/
agents.py:1250-1285), its success the verdict.
"""

from __future__ import annotations

import contextlib
import json
import re
import shlex
import subprocess
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import replace
from typing import Any

from recap.env import Demonstration, EnvError, Environment, InvalidActionError, Reset, Step
from recap.llm import ToolDef
from schemas.kinds import EndReason
from workers.sandbox.base import Sandbox, SandboxError, SandboxLimits, SandboxSpec, episode_failure
from workers.sandbox.session import ShellSession

from . import tools as T
from .evaluate import Evaluation, evaluate, evaluation_record
from .expert import parse_patch, replacements
from .grading import DEFAULT_GRADING, Grading
from .instances import SweInstance
from .rules import goal_text, review_text, rules_text
from .submission_diff import without_build_files

#: mini-SWE-agent's submit line: a command whose output's first line is this hands in the diff
SUBMIT_SENTINEL = "COMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT"
#: default total of output bytes one episode may produce (all its observations together)
DEFAULT_TOTAL_OUTPUT_BYTES = 5_000_000
#: where the submission diff is written inside the sandbox (never part of the diff itself)
SUBMISSION_FILE = ".git/recap-eval-submission.patch"

OpenSandbox = Callable[[SandboxSpec], Sandbox]


class SweEnvironment(Environment):
    """A SWE-bench instance in a sandbox opened at reset (``open_sandbox``), closed by :meth:`close`."""

    benchmark = "swe"
    invalid_action_mode = "step"
    partially_observed = True
    #: the first output line of a text action that submits (the mini_swe method sets its
    #: configuration's: mini-swe-agent 1.0.0 printed another, workers/agents/mini_swe_package.py)
    submit_sentinel = SUBMIT_SENTINEL

    def __init__(
        self,
        instance: SweInstance,
        open_sandbox: OpenSandbox,
        *,
        split: str = "custom",
        limits: SandboxLimits | None = None,
        image: str = SandboxSpec.image,
        labels: Mapping[str, str] | None = None,
        total_output_bytes: int = DEFAULT_TOTAL_OUTPUT_BYTES,
        eval_timeout_s: float | None = None,
        grading: Grading = DEFAULT_GRADING,
        max_timeouts_in_row: int | None = None,
    ) -> None:
        self.instance = instance
        self.instance_id = instance.id
        self.split = split
        self.task = instance.instance_id
        self.limits = limits if limits is not None else SandboxLimits()
        self.max_steps = self.limits.max_commands
        self.total_output_bytes = total_output_bytes
        #: commands in a row that may run past their time limit before the episode ends (None: no
        #: such limit; SWE-agent's max_consecutive_execution_timeouts, 3 in swebench-recap/sweagent/
        #: tools/tools.py:150, after which it hands the work in: agents.py:1033-1040, 1265-1270)
        self.max_timeouts_in_row = max_timeouts_in_row
        self.eval_timeout_s = eval_timeout_s if eval_timeout_s is not None else instance.eval_timeout_s
        self.spec = SandboxSpec(
            repo_path=instance.repo_path,
            base_commit=instance.base_commit,
            image=image,
            limits=self.limits,
            labels=dict(labels or {}),
        )
        self.grading = grading
        self._open = open_sandbox
        self._sandbox: Sandbox | None = None
        #: the ``bash`` tool's session over the episode's sandbox (state carried between calls)
        self._session: ShellSession | None = None
        self._last_workdir = ""
        self.evaluation: Evaluation | None = None
        #: the judged submissions not yet handed over (:meth:`take_records`): evaluation and diff
        self._judged: list[tuple[Evaluation, str]] = []
        self._clear()

    def _clear(self) -> None:
        self._steps_taken = 0
        self._time_used = 0.0
        self._output_used = 0
        self._timeouts_in_row = 0
        self._submit_stage = 0
        self._done = False
        self._viewed: set[str] = set()
        self._commands_run: set[str] = set()
        self._patch = ""
        self.evaluation = None
        #: the editor's changes, for undo_edit
        self._edits = T.EditHistory()

    # -- sandbox ---------------------------------------------------------------------------------
    @property
    def workdir(self) -> str:
        """The repository folder as commands see it (the spec's until a sandbox is open; the last
        sandbox's once the episode's is closed)."""
        if self._sandbox is not None:
            return self._sandbox.workdir
        return self._last_workdir or self.spec.workdir

    def _box(self) -> Sandbox:
        if self._sandbox is None:
            raise EnvError(f"{self.instance_id}: call reset() before acting")
        return self._sandbox

    def _open_clean(self) -> Sandbox:
        """A fresh sandbox at the base commit for the evaluation, its commands allowed the test run's time."""
        t = self.eval_timeout_s
        limits = replace(self.limits, command_timeout_s=max(self.limits.command_timeout_s, t), wall_time_s=t + 600.0)
        return self._open(replace(self.spec, limits=limits))

    # -- episode ---------------------------------------------------------------------------------
    def reset(self) -> Reset:
        """A fresh sandbox at the base commit; the issue text as the first observation."""
        self.close()
        self._clear()
        try:
            self._sandbox = self._open(self.spec)
            self._session = ShellSession(self._sandbox)
        except SandboxError as exc:
            raise episode_failure(self.instance_id, "the sandbox cannot be opened", exc) from exc
        return Reset(observation=self.instance.problem_statement, valid_actions=None, goal=goal_text(self.workdir))

    def tool_defs(self) -> tuple[ToolDef, ...]:
        """bash, view, str_replace, create, insert, undo_edit, submit (:mod:`.tools`), describing this
        episode's limits."""
        return T.tool_defs(self.workdir, self.limits)

    def call_tool(self, name: str, args: Mapping[str, Any]) -> Step:
        """One tool call; a refused one is an ``Error:`` observation with ``info["error"]``."""
        box = self._start_call()
        defs = {t.name: t for t in self.tool_defs()}
        started = time.monotonic()
        with self._sandbox_failures():
            if name not in defs:
                out = T.refused(f"unknown tool {name!r}; the tools are {', '.join(defs)}")
            elif (problem := T.check_args(defs[name], args)) is not None:
                out = T.refused(problem)
            elif name == T.SUBMIT:
                return self._submit(review=True, started=started)
            else:
                out = self._run_tool(box, name, args)
            return self._after(out)  # inside: reaching a limit judges the diff in the sandbox

    def _run_tool(self, box: Sandbox, name: str, args: Mapping[str, Any]) -> T.ToolOutcome:
        if name == T.BASH:
            return self._bash(box, args["command"], self._session)
        if name == T.VIEW:
            out = T.run_view(box, self.limits, args["path"], args.get("view_range"))
            rel = T.repo_relative(box.workdir, args["path"])
            if out.error is None and rel is not None:
                self._viewed.add(rel)
            return out
        if name == T.STR_REPLACE:
            return T.run_str_replace(box, self.limits, args["path"], args["old_str"], args.get("new_str", ""), self._edits)
        if name == T.INSERT:
            return T.run_insert(box, self.limits, args["path"], args["insert_line"], args["new_str"], self._edits)
        if name == T.UNDO_EDIT:
            return T.run_undo_edit(box, self.limits, args["path"], self._edits)
        return T.run_create(box, self.limits, args["path"], args["file_text"], self._edits)

    def _bash(self, box: Sandbox, command: str, session: ShellSession | None = None) -> T.ToolOutcome:
        """Run one shell command (in ``session``: the ``bash`` tool's; else afresh, a text action);
        a command that only prints a file (``cat -n F``, ``sed -n 'a,bp' F``, ``nl F``) counts as
        viewing it, as the ``view`` tool does (the expert plan's views are done once, whichever way
        the agent looked)."""
        self._commands_run.add(command)
        out = T.run_bash(box, self.limits, command, session)
        shown = _printed_file(command)
        rel = T.repo_relative(box.workdir, shown) if shown is not None else None
        if out.error is None and out.exit_code == 0 and rel is not None:
            self._viewed.add(rel)
        return out

    def step(self, action: str) -> Step:
        """The text action: one bash command (mini-SWE-agent); its sentinel output submits at once."""
        if not isinstance(action, str):
            raise InvalidActionError(f"a SWE-bench text action is a bash command string, got {type(action).__name__}")
        box = self._start_call()
        started = time.monotonic()
        with self._sandbox_failures():
            out = self._bash(box, action)
            if out.error is None and _is_sentinel(out.observation, self.submit_sentinel):
                return _as_command(self._submit(review=False, started=started, spent=out))
            return _as_command(self._after(out))  # inside: reaching a limit judges the diff in the sandbox

    @contextlib.contextmanager
    def _sandbox_failures(self) -> Iterator[None]:
        """A sandbox failing under the episode's work ends the episode (:func:`episode_failure`:
        the service's failure is infrastructure, any other the episode's outcome)."""
        try:
            yield
        except SandboxError as exc:
            raise episode_failure(self.instance_id, "the sandbox failed", exc) from exc

    def _start_call(self) -> Sandbox:
        if self._done:  # its sandbox is closed once the diff is judged
            raise EnvError(f"{self.instance_id}: the episode is over; call reset() to play again")
        return self._box()

    def _after(self, out: T.ToolOutcome, extra_s: float = 0.0) -> Step:
        """Count the call against the episode's limits; end the episode when one is reached."""
        self._steps_taken += 1
        self._time_used += out.duration_s + extra_s
        self._output_used += out.output_bytes
        self._timeouts_in_row = self._timeouts_in_row + 1 if out.timed_out else 0
        limit = self._limit_reached()
        if limit is None:
            return Step(out.observation, None, False, False, out.info())
        reason, note = limit
        # the episode ends here; the runtime then hands in the current diff (submit_at_limit),
        # as it does at every other limit
        info = {**out.info(), "end_reason": reason, "limit": note, "detail": note}
        obs = f"{out.observation}\n[{note}: the episode ends and your current changes are submitted]"
        return Step(obs, None, True, False, info)

    def _limit_reached(self) -> tuple[EndReason, str] | None:
        if self._steps_taken >= self.limits.max_commands:
            return "step_cap", f"command limit reached ({self.limits.max_commands} commands)"
        if self._time_used >= self.limits.wall_time_s:
            return "episode_limit", f"time limit reached ({self.limits.wall_time_s:g} seconds of commands)"
        if self._output_used >= self.total_output_bytes:
            return "episode_limit", f"output limit reached ({self.total_output_bytes} bytes in all)"
        if self.max_timeouts_in_row is not None and self._timeouts_in_row >= self.max_timeouts_in_row:
            return "episode_limit", f"timeout limit reached ({self._timeouts_in_row} commands in a row stopped at the time limit)"
        return None

    # -- submission ------------------------------------------------------------------------------
    def current_diff(self) -> str:
        """The repository's changes against the base commit, new files included (it stages everything)."""
        return self._diff_against(self.instance.base_commit)

    def _diff_against(self, base: str) -> str:
        """The changes against ``base`` (a commit or tree) as they are handed in: ``git add -A && git
        diff --cached`` (bin/submit:24) less the binary blocks and byte-code files no ``git apply``
        applies (:func:`.submission_diff.without_build_files`), so that one diff gets one verdict
        whether the evaluation's sandbox has GNU ``patch`` or not."""
        box = self._box()
        res = box.run(f"git add -A && git diff --cached {base} > {SUBMISSION_FILE}")
        if res.exit_code != 0:
            raise SandboxError(f"git diff failed in the sandbox: {res.output.strip()[:300]}")
        return without_build_files(box.read_file(SUBMISSION_FILE).decode("utf-8", errors="replace")).diff

    def _submit(self, *, review: bool, started: float, spent: T.ToolOutcome | None = None) -> Step:
        if review and self._submit_stage == 0:
            self._submit_stage = 1
            diff = self.current_diff()
            out = T.ToolOutcome(observation=review_text(diff), exit_code=0)
            out.output_bytes = len(out.observation.encode("utf-8"))
            text, cut = T.cap_text(out.observation, self.limits.output_bytes)
            out.observation = text + (f"\n[output cut: the first {self.limits.output_bytes} bytes are shown]" if cut else "")
            out.duration_s = time.monotonic() - started
            return self._after(out)
        self._steps_taken += 1
        ev = self._judge()
        base = spent if spent is not None else T.ToolOutcome(observation="", exit_code=0)
        base.duration_s = time.monotonic() - started
        info = {**base.info(), **self._verdict_info(ev)}
        if not ev.success:
            info["end_reason"] = "agent_done"
        return Step(submitted_text(ev), None, True, ev.success, info)

    def submit_at_limit(self, limit: str) -> Step | None:
        """SWE-agent's autosubmission (swebench-recap/sweagent/agent/agents.py:888-933): at a limit
        (``limit``: which one) the repository's diff is taken as a submission does it and, when
        it is not empty, judged like a submitted one (its ``evaluations`` row is written); None
        for an empty diff (nothing was handed in: the release's submission is then empty too,
        :911-915), once the episode is judged, or before reset. A sandbox that fails here ends the
        episode as a tool call's failure does."""
        if self._done or self._sandbox is None:
            return None
        with self._sandbox_failures():
            if not self.current_diff().strip():
                return None
            ev = self._judge()
        info = {**self._verdict_info(ev), "limit": limit, "autosubmitted": True}
        return Step(submitted_text(ev), None, True, ev.success, info)

    def _judge(self) -> Evaluation:
        """Take the diff, end the episode, judge the diff on a clean copy. The episode's sandbox
        is closed first: an episode never holds two containers, so ``ray.sandboxes_per_node``
        bounds the evaluations' containers too."""
        diff = self.current_diff()
        self._done = True
        self.close()
        self.evaluation = self._evaluate(diff)
        self._patch = diff
        self._judged.append((self.evaluation, diff))
        return self.evaluation

    def _evaluate(self, diff: str) -> Evaluation:
        """The verdict on ``diff``: our evaluation in a clean copy, graded per ``grading`` (:mod:`.evaluate`)."""
        return evaluate(self.instance, diff, self._open_clean, grading=self.grading, eval_timeout_s=self.eval_timeout_s)

    def _verdict_info(self, ev: Evaluation) -> dict[str, Any]:
        """The verdict in the step's info: the deciding one (``resolved``, ``eval_reason``) and,
        when the official grading ran, its status (``official_status``)."""
        info: dict[str, Any] = {
            "patch": self._patch,
            "resolved": ev.success,
            "eval_reason": ev.verdict_reason,
            "tests": dict(ev.tests),
            "graded_by": ev.graded_by,
        }
        if ev.official is not None:
            info["official_status"] = ev.official.status
        return info

    def take_records(self, episode_id: str, run_id: str) -> list[Any]:
        """The ``evaluations`` row of each submission judged since the last call
        (:class:`~schemas.records.EvaluationRecord`), each handed over once."""
        judged, self._judged = self._judged, []
        return [evaluation_record(episode_id, self.instance, ev, patch) for ev, patch in judged]

    # -- prompt material -------------------------------------------------------------------------
    def rules(self) -> str:
        """Where the repository is, the tools, the limits, no network, tests left alone (:mod:`.rules`)."""
        return rules_text(self.workdir, self.limits, self.total_output_bytes, SUBMIT_SENTINEL)

    def demonstration(self) -> Demonstration | None:
        """None: the paper runs SWE-bench with no demonstration (appendix, SWE-bench details)."""
        return None

    # -- the offline expert ----------------------------------------------------------------------
    def expert_plan(self) -> list[str] | None:
        """The rest of the gold patch's play as JSON tool calls (``{"name", "arguments"}``): for each
        file not yet as the gold patch leaves it, view it (once), put it back at the base commit
        when it was changed otherwise, then one ``str_replace`` per hunk (``create`` for a new file);
        then the FAIL_TO_PASS tests' files through bash (once; the tests themselves arrive with the
        evaluation's test patch) and ``submit`` twice (review, then final).
        None once the episode is over, or for a gold patch with binary files. It reads the sandbox's
        files, so a sandbox that fails here ends the episode as a tool call's would."""
        if self._done:
            return None
        files = parse_patch(self.instance.patch)
        if any(f.binary for f in files):
            return None
        calls: list[dict[str, Any]] = []
        with self._sandbox_failures():
            for f in files:
                calls += self._expert_file(f)
        test_files = dict.fromkeys(t.split("::", 1)[0] for t in self.instance.fail_to_pass)  # the new tests are not here yet
        test = f"{self.instance.test_cmd} " + " ".join(_quote(f) for f in test_files)
        if self._submit_stage == 0 and test not in self._commands_run:
            calls.append({"name": T.BASH, "arguments": {"command": test}})
        calls += [{"name": T.SUBMIT, "arguments": {}}] * (2 - self._submit_stage)
        return [json.dumps(c) for c in calls]

    def _expert_file(self, f: Any) -> list[dict[str, Any]]:
        shown = T.shown_path(self.workdir, f.path)
        base = self._base_text(f.old_path) if f.old_path is not None else None
        current = self._current_text(f.path)
        if f.new_path is None:  # deleted by the gold patch
            return [] if current is None else [{"name": T.BASH, "arguments": {"command": f"rm {_quote(shown)}"}}]
        pairs, gold = replacements(base or "", f.hunks)
        if current == gold:
            return []
        calls: list[dict[str, Any]] = []
        if base is None:  # created by the gold patch
            if current is not None:
                calls.append({"name": T.BASH, "arguments": {"command": f"rm {_quote(shown)}"}})
            return [*calls, {"name": T.CREATE, "arguments": {"path": shown, "file_text": gold}}]
        if f.path not in self._viewed:
            calls.append({"name": T.VIEW, "arguments": {"path": shown}})
        if current != base:
            ref = _quote(self.instance.base_commit)
            calls.append({"name": T.BASH, "arguments": {"command": f"git checkout {ref} -- {_quote(f.path)}"}})
        calls += [{"name": T.STR_REPLACE, "arguments": {"path": shown, "old_str": o, "new_str": n}} for o, n in pairs]
        return calls

    def _base_text(self, path: str) -> str:
        proc = subprocess.run(
            ["git", "-C", self.instance.repo_path, "show", f"{self.instance.base_commit}:{path}"],
            capture_output=True,
            check=False,
        )
        if proc.returncode != 0:
            raise EnvError(f"{self.instance_id}: the gold patch names {path}, which the base commit lacks")
        return proc.stdout.decode("utf-8", errors="replace")

    def _current_text(self, path: str) -> str | None:
        if self._sandbox is None:
            return self._base_text(path) if self._exists_at_base(path) else None
        try:
            return self._sandbox.read_file(path).decode("utf-8", errors="replace")
        except (FileNotFoundError, IsADirectoryError):
            return None

    def _exists_at_base(self, path: str) -> bool:
        proc = subprocess.run(
            ["git", "-C", self.instance.repo_path, "cat-file", "-e", f"{self.instance.base_commit}:{path}"],
            capture_output=True,
            check=False,
        )
        return proc.returncode == 0

    def close(self) -> None:
        """Close the episode's sandbox (safe to call twice)."""
        box, self._sandbox = self._sandbox, None
        self._session = None
        if box is not None:
            self._last_workdir = box.workdir
            box.close()


def _is_sentinel(output: str, sentinel: str = SUBMIT_SENTINEL) -> bool:
    """Whether a command's output starts with the submit line (mini-SWE-agent: first line, stripped)."""
    return output.lstrip().split("\n", 1)[0].strip() == sentinel


def _quote(text: str) -> str:
    return shlex.quote(text)


def submitted_text(ev: Evaluation) -> str:
    """The final observation: the submission was taken, and (for the record) how it was judged."""
    failing = ev.failing_tests()
    verdict = {
        "resolved": "it resolves the issue (every listed test passes)",
        "no_patch": "it changes nothing",
        "patch_failed": "it does not apply to a clean copy of the repository",
        "patch_refused": "it was refused unapplied: it writes outside the repository ('..', an absolute path, .git, or a symlink out)",
        "tests_failed": f"tests still fail: {', '.join(failing)}",
        "timeout": "the tests ran past the time limit",
    }[ev.verdict_reason]
    return f"Your changes were submitted; {verdict}."


def _printed_file(command: str) -> str | None:
    """The one file a command that only prints it names (``cat [-n] F``, ``nl F``, ``sed -n 'a,bp' F``);
    None for any other command."""
    try:
        words = shlex.split(command)
    except ValueError:
        return None
    if len(words) == 2 and words[0] in ("cat", "nl"):
        return words[1]
    if len(words) == 3 and words[:2] == ["cat", "-n"]:
        return words[2]
    if len(words) == 4 and words[:2] == ["sed", "-n"] and re.fullmatch(r"\d+,(\d+|\$)p", words[2]):
        return words[3]
    return None


def _as_command(step: Step) -> Step:
    """A text action's step, marked as the shell command it ran (``info["tool"]``), so its
    ``tool_calls`` row is written like a tool call's (recap.runtime.EnvDriver.execute)."""
    return replace(step, info={**step.info, "tool": T.BASH})
