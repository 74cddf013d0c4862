"""The SWE environment end to end on the fixtures: review then submit, the expert's play, the text
(bash + sentinel) path, the episode limits, and the benchmark's options and refusals."""

from __future__ import annotations

import json
from collections.abc import Callable

import pytest

from recap.env import EnvError, UnknownInstanceError
from tests.workers.envs.swe.sandbox_log import SandboxLog
from workers.envs.registry import get_benchmark, make_env
from workers.envs.swe.env import SweEnvironment
from workers.envs.swe.examples import Fixtures
from workers.envs.swe.rules import review_text

NAMES = ("offbyone", "format", "twofiles", "newfunc", "hang", "p2p")


def _play_expert(env: SweEnvironment) -> list[str]:
    """Play the expert plan one call at a time (asking again after each) until the episode ends."""
    names = []
    for _ in range(30):
        plan = env.expert_plan()
        assert plan
        call = json.loads(plan[0])
        step = env.call_tool(call["name"], call["arguments"])
        assert step.info["error"] is None, step.observation
        names.append(call["name"])
        if step.done:
            assert step.success, step.info
            return names
    raise AssertionError("the expert did not finish")


def test_reset_gives_the_issue_and_the_goal(swe_env: Callable[..., SweEnvironment], fixtures: Fixtures) -> None:
    env = swe_env("offbyone")
    r = env.reset()
    assert r.observation == "count_range(a, b) should include b: count_range(1, 3) must be [1, 2, 3] but it returns [1, 2]."
    assert r.goal == f"Change the code in the repository at {env.workdir} so that the issue described above is resolved."
    assert r.valid_actions is None
    assert (env.benchmark, env.split, env.task, env.instance_id) == (
        "swe",
        "tasks",
        "fixture__offbyone-1",
        "swe/fixture__offbyone-1",
    )
    assert (env.invalid_action_mode, env.max_steps, env.demonstration()) == ("step", 250, None)
    assert f"checked out at {env.workdir}" in env.rules()


@pytest.mark.parametrize("name", NAMES)
def test_expert_plan_played_through_call_tool_resolves(swe_env: Callable[..., SweEnvironment], name: str) -> None:
    env = swe_env(name, command_timeout_s=20)
    env.reset()
    names = _play_expert(env)
    assert names[-2:] == ["submit", "submit"]
    assert env.evaluation is not None and env.evaluation.reason == "resolved"
    assert env.expert_plan() is None


def test_expert_plan_before_reset_and_after_a_stray_edit(swe_env: Callable[..., SweEnvironment]) -> None:
    env = swe_env("twofiles")
    plan = [json.loads(c) for c in env.expert_plan() or []]
    assert [(c["name"], c["arguments"].get("path")) for c in plan] == [
        ("view", "/repo/convert.py"),
        ("str_replace", "/repo/convert.py"),
        ("view", "/repo/units.py"),
        ("str_replace", "/repo/units.py"),
        ("bash", None),
        ("submit", None),
        ("submit", None),
    ]
    assert plan[3]["arguments"] == {
        "path": "/repo/units.py",
        "old_str": "CM_PER_INCH = 2.45\n",
        "new_str": "CM_PER_INCH = 2.54\n",
    }
    env.reset()
    env.call_tool("bash", {"command": "echo '# scratch' >> units.py"})
    plan = [json.loads(c) for c in env.expert_plan() or []]
    assert plan[2:5] == [
        {"name": "view", "arguments": {"path": f"{env.workdir}/units.py"}},
        {"name": "bash", "arguments": {"command": f"git checkout {env.instance.base_commit} -- units.py"}},
        {
            "name": "str_replace",
            "arguments": {
                "path": f"{env.workdir}/units.py",
                "old_str": "CM_PER_INCH = 2.45\n",
                "new_str": "CM_PER_INCH = 2.54\n",
            },
        },
    ]
    _play_expert(env)


def test_review_then_submit(swe_env: Callable[..., SweEnvironment], sandboxes: SandboxLog) -> None:
    env = swe_env("newfunc")
    env.reset()
    env.call_tool("create", {"path": "repro.py", "file_text": "print(1)\n"})
    first = env.call_tool("submit", {})
    diff = (
        "diff --git a/repro.py b/repro.py\nnew file mode 100644\nindex 0000000..b917a72\n--- /dev/null\n+++ b/repro.py\n"
        "@@ -0,0 +1 @@\n+print(1)\n"
    )
    assert first.observation == review_text(diff)
    assert first.observation.endswith(f"<diff>\n{diff}</diff>")
    assert (first.done, first.success, first.info["error"]) == (False, False, None)
    second = env.call_tool("submit", {})
    assert (second.done, second.success) == (True, False)
    assert second.observation == "Your changes were submitted; tests still fail: tests/test_textutil.py::test_slugify."
    assert second.info["end_reason"] == "agent_done"
    assert second.info["patch"] == diff
    assert (second.info["resolved"], second.info["eval_reason"]) == (False, "tests_failed")
    assert second.info["tests"] == {
        "tests/test_textutil.py::test_slugify": "FAILED",
        "tests/test_textutil.py::test_words": "PASSED",
    }
    assert env.steps_taken == 3
    with pytest.raises(EnvError, match="the episode is over"):
        env.call_tool("bash", {"command": "ls"})
    env.close()
    assert all(box.closed for box in sandboxes.opened)
    assert len(sandboxes.opened) == 2  # the episode's sandbox and the evaluation's clean one


def test_text_actions_and_the_submit_sentinel(swe_env: Callable[..., SweEnvironment]) -> None:
    env = swe_env("offbyone")
    env.reset()
    step = env.step("sed -i 's/range(a, b))/range(a, b + 1))/' mathutil.py && grep -n 'b + 1' mathutil.py")
    assert (step.observation, step.done) == ("3:    return list(range(a, b + 1))", False)
    assert step.info["exit_code"] == 0
    final = env.step("echo COMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT && git status --short")
    assert (final.done, final.success) == (True, True)
    assert final.observation == "Your changes were submitted; it resolves the issue (every listed test passes)."
    assert "end_reason" not in final.info
    assert final.info["patch"].startswith("diff --git a/mathutil.py b/mathutil.py\n")
    assert env.steps_taken == 2


def test_sentinel_must_be_the_first_line(swe_env: Callable[..., SweEnvironment]) -> None:
    env = swe_env("offbyone")
    env.reset()
    step = env.step("echo x; echo COMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT")
    assert (step.observation, step.done) == ("x\nCOMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT", False)


def test_command_limit_ends_the_episode_and_submits(swe_env: Callable[..., SweEnvironment]) -> None:
    env = swe_env("format", max_commands=2)
    env.reset()
    assert env.max_steps == 2
    first = env.call_tool("bash", {"command": "echo one"})
    assert first.done is False
    last = env.call_tool("nope", {})
    assert last.done is True and last.success is False
    assert last.observation == (
        "Error: unknown tool 'nope'; the tools are bash, view, str_replace, create, insert, undo_edit, submit\n"
        "[command limit reached (2 commands): the episode ends and your current changes are submitted]"
    )
    assert (last.info["end_reason"], last.info["limit"], "eval_reason" in last.info) == (
        "step_cap",
        "command limit reached (2 commands)",
        False,  # judged by the runtime's submit_at_limit, not here
    )
    # nothing was changed: nothing is handed in, nothing judged
    assert env.submit_at_limit("step_cap: 2 steps (cap 2)") is None
    assert env.take_records("e", "r") == []


def test_at_a_limit_a_non_empty_diff_is_handed_in_and_judged(swe_env: Callable[..., SweEnvironment]) -> None:
    env = swe_env("format", max_commands=2)
    env.reset()
    env.call_tool("str_replace", {"path": "shop.py", "old_str": "{cents / 100}", "new_str": "{cents / 100:.2f}"})
    last = env.call_tool("bash", {"command": "echo two"})
    assert (last.done, last.success, last.info["end_reason"]) == (True, False, "step_cap")
    step = env.submit_at_limit("step_cap: 2 steps (cap 2)")
    assert step is not None
    assert (step.done, step.success, step.info["autosubmitted"], step.info["limit"], step.info["eval_reason"]) == (
        True,
        True,
        True,
        "step_cap: 2 steps (cap 2)",
        "resolved",
    )
    assert step.observation == "Your changes were submitted; it resolves the issue (every listed test passes)."
    (row,) = env.take_records("e", "r")
    assert (row.episode_id, row.resolved, row.reason) == ("e", True, "resolved")
    assert row.patch == step.info["patch"] and '+    return f"${cents / 100:.2f}"' in row.patch
    assert env.submit_at_limit("again") is None  # judged once


def test_output_limit_is_an_episode_limit(swe_env: Callable[..., SweEnvironment]) -> None:
    env = swe_env("format", total_output_bytes=10)
    env.reset()
    step = env.call_tool("bash", {"command": "echo 0123456789"})
    assert step.done is True
    assert (step.info["end_reason"], step.info["limit"]) == ("episode_limit", "output limit reached (10 bytes in all)")


def test_acting_before_reset_is_an_env_error(swe_env: Callable[..., SweEnvironment]) -> None:
    env = swe_env("format")
    with pytest.raises(EnvError, match="call reset"):
        env.step("ls")


# -- the benchmark --------------------------------------------------------------------------------
def test_benchmark_lists_by_file_repository_and_id(fixtures: Fixtures) -> None:
    bench = get_benchmark("swe")
    opts = {"instances_file": str(fixtures.tasks_file)}
    assert bench.list_instances_for(None, opts) == [f"swe/fixture__{n}-1" for n in NAMES]
    assert bench.list_instances_for("fixture/hang", opts) == ["swe/fixture__hang-1"]
    assert bench.list_instances_for("swe/fixture__p2p-1", opts) == ["swe/fixture__p2p-1"]
    with pytest.raises(UnknownInstanceError) as err:
        bench.list_instances_for("nope", opts)
    assert str(err.value) == (
        f"no SWE-bench record in {fixtures.tasks_file} is 'nope'; selectors: all, a repository (owner/name), an instance id"
    )
    with pytest.raises(ValueError) as missing:
        bench.list_instances(None)
    assert str(missing.value) == "swe needs options.instances_file: a JSONL file of SWE-bench records, each with a repo_path"


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (
            {"sandbox": "vm"},
            "sandbox must be 'docker' or 'local' ('local' runs the model's commands on this host as this user: it is not isolation), got 'vm'",
        ),
        ({"network": "yes"}, "network must be true or false, got 'yes'"),
        ({"max_commands": 0}, "max_commands must be a positive integer, got 0"),
        ({"command_timeout_s": -1}, "command_timeout_s must be a positive number, got -1"),
        ({"output_bytes": 1.5}, "output_bytes must be a positive integer, got 1.5"),
        ({"image": ""}, "image must be a docker image name, got ''"),
        ({"max_timeouts_in_row": 0}, "max_timeouts_in_row must be a positive integer, got 0"),
        (
            {"colour": 1},
            "unknown swe option(s) colour; accepted: instances_file, sandbox, sandbox_trust, image, network, command_timeout_s, output_bytes, max_commands, wall_time_s, total_output_bytes, max_timeouts_in_row, eval_timeout_s, grading, step_multiplier, seed",
        ),
    ],
)
def test_bad_options(fixtures: Fixtures, sandboxes: SandboxLog, options: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError) as err:
        make_env("swe/fixture__format-1", instances_file=str(fixtures.tasks_file), open_sandbox=sandboxes, **options)
    assert str(err.value) == message


def test_make_opens_no_sandbox_and_carries_the_options(fixtures: Fixtures, sandboxes: SandboxLog) -> None:
    env = make_env(
        "swe/fixture__format-1",
        instances_file=str(fixtures.tasks_file),
        open_sandbox=sandboxes,
        network=True,
        command_timeout_s=7,
        wall_time_s=100,
        image="local/img:1",
        step_multiplier=2.0,
        seed=3,
    )
    assert isinstance(env, SweEnvironment)
    assert sandboxes.opened == []
    assert (env.spec.image, env.spec.limits.network, env.spec.limits.command_timeout_s, env.spec.limits.wall_time_s) == (
        "local/img:1",
        True,
        7.0,
        100.0,
    )
    with pytest.raises(UnknownInstanceError) as err:
        make_env("swe/fixture__none-1", instances_file=str(fixtures.tasks_file), open_sandbox=sandboxes)
    assert str(err.value) == f"no SWE-bench record 'fixture__none-1' in {fixtures.tasks_file}"


def test_methods_that_cannot_act_are_refused() -> None:
    bench = get_benchmark("swe")
    assert bench.refuses_method("recap") is None
    assert bench.refuses_method("react") is None
    for method in ("cot", "standard", "act", "adapt"):
        reason = bench.refuses_method(method)
        assert reason and "\n" not in reason
    assert bench.canonical_id("swe/django__django-1") == "swe/django__django-1"
    with pytest.raises(UnknownInstanceError):
        bench.canonical_id("swe/")


def test_the_bash_tool_keeps_one_session_and_a_text_action_starts_afresh(swe_env: Callable[..., SweEnvironment]) -> None:
    env = swe_env("format", command_timeout_s=2)
    env.reset()
    root = env.workdir
    assert env.call_tool("bash", {"command": "mkdir -p scratch && cd scratch && export MARK=7"}).observation == "[no output]"
    assert env.call_tool("bash", {"command": "pwd; echo $MARK"}).observation == f"{root}/scratch\n7"
    slow = env.call_tool("bash", {"command": "cd / && sleep 30"})
    assert slow.observation == (
        "[the command was stopped after 2 seconds]\n[the shell session goes on from its state before this command]"
    )
    assert slow.info["timed_out"] is True
    assert env.call_tool("bash", {"command": "pwd"}).observation == f"{root}/scratch"
    # mini-SWE-agent's text actions each run in a fresh subprocess in the repository folder
    assert env.step('pwd; echo "${MARK-unset}"').observation == f"{root}\nunset"


def test_commands_timing_out_in_a_row_reach_the_timeout_limit(swe_env: Callable[..., SweEnvironment]) -> None:
    env = swe_env("format", command_timeout_s=1, max_timeouts_in_row=2)
    env.reset()
    assert env.call_tool("bash", {"command": "sleep 5"}).done is False
    assert env.call_tool("bash", {"command": "true"}).done is False  # a command in time starts the count again
    assert env.call_tool("bash", {"command": "sleep 5"}).done is False
    last = env.call_tool("bash", {"command": "sleep 5"})
    assert (last.done, last.info["end_reason"], last.info["limit"]) == (
        True,
        "episode_limit",
        "timeout limit reached (2 commands in a row stopped at the time limit)",
    )
