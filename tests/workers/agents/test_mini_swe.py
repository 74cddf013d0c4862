"""The mini_swe method: mini-SWE-agent's own DefaultAgent loop (the package, 1.x) on our
conversation and our sandboxed SWE-bench environment (fixture tasks, local sandboxes)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest
import yaml
from jinja2 import StrictUndefined, Template

import workers.episode_worker  # noqa: F401  registers mini_swe as the driver and workers do
from recap.blocksworld import BlocksworldEnv
from recap.config import ConfigError
from recap.methods import METHODS, make_agent
from recap.scripted import ScriptedClient
from schemas.records import CallRecord, MessageRecord, StepRecord, ToolCallRecord
from tests.doubles.offline_expert_client import OfflineExpert
from workers.agents.mini_swe import MiniSweAgent, MiniSweConfig
from workers.agents.mini_swe_package import command_output, load_package
from workers.envs.registry import get_benchmark
from workers.envs.swe.env import SweEnvironment

pytest.importorskip("minisweagent")

SUBMIT = "echo COMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT && git add -A && git diff --cached"
FIX = "sed -i 's/list(range(a, b))/list(range(a, b + 1))/' mathutil.py"


def reply(command: str, thought: str = "next") -> str:
    return f"THOUGHT: {thought}\n\n```bash\n{command}\n```"


def package_yaml() -> dict:
    from minisweagent.config import builtin_config_dir

    return yaml.safe_load((Path(builtin_config_dir) / "extra" / "swebench.yaml").read_text())["agent"]


def render(template: str, **values) -> str:
    return Template(template, undefined=StrictUndefined).render(**values)


def run(env: SweEnvironment, client, agent: MiniSweAgent | None = None):
    records: list = []
    result = (agent or make_agent("mini_swe")).run(env, client, episode_id="ep", emit=records.append)
    return result, records


def of(records: list, cls: type) -> list:
    return [r for r in records if isinstance(r, cls)]


def test_a_scripted_episode_sends_the_packages_messages_runs_the_commands_and_submits(swe_env: Callable[..., SweEnvironment]):
    env = swe_env("offbyone")
    client = ScriptedClient([reply("cat mathutil.py", "look"), reply(FIX, "fix"), reply(SUBMIT, "done")])
    result, records = run(env, client)

    assert (result.end_reason, result.success, result.steps, result.llm_calls, result.json_repairs) == ("success", True, 3, 3, 0)
    # the first request: the package's system text and its SWE-bench task text with the issue (our
    # repository folder in place of /testbed), nothing else
    agent = package_yaml()
    problem = env.instance.problem_statement
    system = render(agent["system_template"])
    task = render(agent["instance_template"].replace("/testbed", env.workdir), task=problem)
    assert [(m.role, m.content) for m in client.requests[0].messages] == [("system", system), ("user", task)]
    # every observation as the package's template shows it: return code, then the output
    source = (Path(env.instance.repo_path) / "mathutil.py").read_text().rstrip("\n")
    assert [(m.role, m.content) for m in client.requests[2].messages[2:]] == [
        ("assistant", reply("cat mathutil.py", "look")),
        ("user", f"<returncode>0</returncode>\n<output>\n{source}</output>"),
        ("assistant", reply(FIX, "fix")),
        ("user", "<returncode>0</returncode>\n<output>\n</output>"),
    ]
    assert [r.purpose for r in client.requests] == ["task", "observation", "observation"]
    first = client.requests[0]
    assert (first.temperature, first.max_tokens, first.json_mode, first.tools) == (0.0, None, False, ())
    assert {k: first.hints[k] for k in ("style", "text_layout", "reply_fields", "valid_actions")} == {
        "style": "mini_swe",
        "text_layout": "bash_block",
        "reply_fields": ("think", "action"),
        "valid_actions": None,
    }
    # the commands ran through our driver: one tool_calls row and one steps row each
    assert [(t.name, t.arguments, t.exit_code) for t in of(records, ToolCallRecord)] == [
        ("bash", '{"command": "cat mathutil.py"}', 0),
        ("bash", '{"command": "sed -i \'s/list(range(a, b))/list(range(a, b + 1))/\' mathutil.py"}', 0),
        ("bash", '{"command": "' + SUBMIT + '"}', 0),
    ]
    assert [s.action for s in of(records, StepRecord)] == ["cat mathutil.py", FIX, SUBMIT]
    # the messages rows are the package's conversation, with its closing message (the submission)
    messages = of(records, MessageRecord)
    assert [(m.seq, m.role, m.kind, m.pinned) for m in messages] == [
        (0, "system", "system", True),
        (1, "user", "task", True),
        (2, "assistant", "reply", False),
        (3, "user", "observation", False),
        (4, "assistant", "reply", False),
        (5, "user", "observation", False),
        (6, "assistant", "reply", False),
        (7, "user", "exit", False),
    ]
    assert messages[-1].content == "Your changes were submitted; it resolves the issue (every listed test passes)."
    assert [c.response_seq for c in of(records, CallRecord)] == [2, 4, 6]
    assert env.evaluation is not None and env.evaluation.resolved


def test_a_reply_without_or_with_two_bash_blocks_gets_the_packages_format_error(swe_env: Callable[..., SweEnvironment]):
    env = swe_env("offbyone")
    two = reply("ls") + "\n\nand also\n\n```bash\npwd\n```"
    client = ScriptedClient(["I will just think.", two, reply("ls nope"), reply("echo COMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT")])
    result, records = run(env, client)

    assert (result.end_reason, result.steps, result.llm_calls, result.json_repairs) == ("agent_done", 2, 4, 2)
    error = package_yaml()["format_error_template"]
    sent = [(m.role, m.content) for m in client.requests[3].messages[2:]]
    assert sent == [
        ("assistant", "I will just think."),
        ("user", render(error, actions=[])),
        ("assistant", two),
        ("user", render(error, actions=["ls", "pwd"])),
        ("assistant", reply("ls nope")),
        # a failing command: its return code in the template, not our "[exit code 2]" line
        ("user", "<returncode>2</returncode>\n<output>\nls: cannot access 'nope': No such file or directory</output>"),
    ]
    assert sent[1][1].startswith("Please always provide EXACTLY ONE action in triple backticks, found 0 actions.\n")
    assert sent[3][1].startswith("Please always provide EXACTLY ONE action in triple backticks, found 2 actions.\n")
    assert [r.purpose for r in client.requests] == ["task", "format_error", "format_error", "observation"]
    assert [m.kind for m in of(records, MessageRecord)][2:] == [
        "reply",
        "format_error",
        "reply",
        "format_error",
        "reply",
        "observation",
        "reply",
        "exit",
    ]
    assert [s.action for s in of(records, StepRecord)] == ["ls nope", "echo COMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT"]
    assert of(records, MessageRecord)[-1].content == "Your changes were submitted; it changes nothing."


def test_the_packages_step_limit_is_the_runs_call_cap(swe_env: Callable[..., SweEnvironment]):
    env = swe_env("offbyone")
    client = ScriptedClient([reply("ls"), reply("pwd"), reply("ls")])
    agent = make_agent("mini_swe", max_llm_calls=2)
    result, records = run(env, client, agent)

    assert (result.end_reason, result.error, result.llm_calls, result.steps) == (
        "call_cap",
        "2 model calls (mini-SWE-agent's step_limit 2)",
        2,
        2,
    )
    assert client.remaining == 1
    kinds = [(m.kind, m.content[:12]) for m in of(records, MessageRecord)][-2:]
    assert kinds == [("observation", "<returncode>"), ("exit", "")]


def test_the_derived_call_cap_is_the_step_cap_and_the_cost_limit_is_the_packages(swe_env: Callable[..., SweEnvironment]):
    agent = make_agent("mini_swe", benchmark=get_benchmark("swe"), profile="paper")
    env = swe_env("offbyone", max_commands=7)
    cfg = agent.episode_config(env)
    assert (cfg.max_llm_calls, cfg.max_episode_cost_usd, cfg.temperature, cfg.json_mode) == (7, 3.0, 0.0, False)
    assert cfg.history_window() == 10**9  # the package sends every message: no window


@pytest.mark.parametrize("name", ["offbyone", "twofiles", "newfunc"])
def test_the_offline_expert_solves_a_fixture_through_the_package_loop(swe_env: Callable[..., SweEnvironment], name: str):
    env = swe_env(name)
    client = OfflineExpert(env)
    result, records = run(env, client)

    assert (result.end_reason, result.success, result.json_repairs) == ("success", True, 0)
    commands = [s.action for s in of(records, StepRecord)]
    assert commands[-1] == "echo COMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT"
    assert result.llm_calls == result.steps == len(commands)
    assert [m.role for m in client.requests[0].messages] == ["system", "user"]


def test_command_output_drops_only_the_markers_the_template_already_says():
    assert command_output("[no output]", 0) == ""
    assert command_output("[exit code 1]", 1) == ""
    assert command_output("oops\n[exit code 1]", 1) == "oops"
    assert command_output("oops\n[exit code 1]", 2) == "oops\n[exit code 1]"
    assert command_output("out\n[output cut: the first 10 of 99 bytes are shown]", 0) == (
        "out\n[output cut: the first 10 of 99 bytes are shown]"
    )


def test_registration_settings_and_refusals():
    assert METHODS.get("mini_swe") == (MiniSweAgent, MiniSweConfig)
    with pytest.raises(ConfigError, match="json_mode must be false"):
        make_agent("mini_swe", json_mode=True)
    package = load_package()
    assert package.version.startswith("1.")
    assert (package.agent_settings["step_limit"], package.agent_settings["cost_limit"]) == (250, 3.0)


def test_mini_swe_refuses_an_environment_without_tools():
    env = BlocksworldEnv([["A", "C"], ["B"]], ["A", "B", "C"], instance_id="blocksworld/test", demo=False)
    result = make_agent("mini_swe").run(env, ScriptedClient([]))
    assert (result.end_reason, result.llm_calls) == ("env_error", 0)
    assert result.error is not None and "mini_swe runs only on a coding benchmark" in result.error


def test_mini_swe_on_a_benchmark_without_tools_is_refused_before_anything_runs(tmp_path, capsys):
    from pipeline.cli import main

    spec = tmp_path / "sweep.yaml"
    spec.write_text(
        f"run: r\noutput: {tmp_path / 'out'}\nmodels: [{{model: offline/expert}}]\n"
        "methods: [{method: mini_swe}]\nenvironments: [{benchmark: blocksworld, tasks: ['3'], limit: 1}]\n"
    )
    assert main(["run", str(spec), "--progress", "off"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        "recap: error: sweep.yaml: methods[0] (mini_swe) cannot run on blocksworld/3: "
        "mini_swe runs only on a coding benchmark (swe, swe-verified), not on blocksworld"
    ]
    assert not (tmp_path / "out").exists()  # nothing written
