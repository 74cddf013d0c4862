"""``mini_swe`` under ``profile: released``: mini-swe-agent 1.0.0's SWE-bench configuration (the
version of the leaderboard run behind the paper's 39.58 %), whatever version is installed."""

from __future__ import annotations

import dataclasses
import hashlib
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml
from jinja2 import Template

import workers.episode_worker  # noqa: F401  registers mini_swe as the driver and workers do
from recap.methods import make_agent
from recap.scripted import ScriptedClient
from schemas.records import MessageRecord, StepRecord
from tests.doubles.offline_expert_client import OfflineExpert
from workers.agents import mini_swe_package
from workers.agents.mini_swe import MiniSweConfig
from workers.envs.registry import get_benchmark
from workers.envs.swe.env import SweEnvironment

pytest.importorskip("minisweagent")

SHIPPED = Path(mini_swe_package.__file__).parent / "mini_swe_1_0_0"
SENTINEL_1_0_0 = "MICRO_SWE_AGENT_FINAL_OUTPUT"
SUBMIT_1_0_0 = f"echo {SENTINEL_1_0_0} && git add -A && git diff --cached"
FIX = "sed -i 's/list(range(a, b))/list(range(a, b + 1))/' mathutil.py"


def reply(command: str, thought: str = "next") -> str:
    return f"THOUGHT: {thought}\n\n```bash\n{command}\n```"


def config_1_0_0() -> dict[str, Any]:
    return yaml.safe_load((SHIPPED / "swebench.yaml").read_text())["agent"]


def released_agent():
    return make_agent("mini_swe", profile="released", benchmark=get_benchmark("swe"))


@pytest.fixture
def spied(monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    """The settings the package's agent class is built with (its ``config`` as a dict)."""
    seen: dict[str, Any] = {}
    real = mini_swe_package.load_package

    def spy(config: str = mini_swe_package.INSTALLED) -> mini_swe_package.Package:
        pkg = real(config)

        class Spy(pkg.agent_cls):  # type: ignore[name-defined]
            def __init__(self, *args: Any, **kwargs: Any) -> None:
                super().__init__(*args, **kwargs)
                seen.update(dataclasses.asdict(self.config))

        return dataclasses.replace(pkg, agent_cls=Spy)

    monkeypatch.setattr(mini_swe_package, "load_package", spy)
    return seen


def run(env: SweEnvironment, client, agent=None):
    records: list = []
    result = (agent or released_agent()).run(env, client, episode_id="ep", emit=records.append)
    return result, records


def test_the_shipped_configuration_is_1_0_0s_file_with_its_licence() -> None:
    readme = (SHIPPED / "README.md").read_text()
    digest = hashlib.sha256((SHIPPED / "swebench.yaml").read_bytes()).hexdigest()
    assert f"file sha256\n  `{digest}`" in readme
    assert (
        (SHIPPED / "LICENSE.md")
        .read_text()
        .startswith("MIT License\n\nCopyright (c) 2025 Kilian A. Lieret and Carlos E. Jimenez")
    )
    agent = config_1_0_0()
    assert (agent["step_limit"], agent["cost_limit"]) == (0, 3.0)
    assert f"echo {SENTINEL_1_0_0} && git add -A && git diff --cached" in agent["instance_template"]


def test_released_selects_1_0_0_and_paper_keeps_the_installed_configuration() -> None:
    released = released_agent().config
    paper = make_agent("mini_swe", profile="paper", benchmark=get_benchmark("swe")).config
    assert isinstance(released, MiniSweConfig) and isinstance(paper, MiniSweConfig)
    assert (released.package_config, released.max_episode_cost_usd, released.temperature) == ("1.0.0", 3.0, 0.0)
    assert paper.package_config == "installed"
    assert "package_config" not in paper.to_json()  # the hash of units planned before it is unchanged
    assert MiniSweConfig.from_json(paper.to_json()) == paper and MiniSweConfig.from_json(released.to_json()) == released
    installed = mini_swe_package.load_package()
    assert installed.agent_settings["step_limit"] != 0  # what the installed version would have run (250)


def test_under_released_the_agent_gets_1_0_0s_templates_limits_and_sentinel(
    swe_env: Callable[..., SweEnvironment], spied: dict[str, Any]
) -> None:
    env = swe_env("offbyone", max_commands=50)
    client = ScriptedClient(
        [
            reply("echo COMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT", "the installed version's line: 1.0.0 did not submit on it"),
            "THOUGHT: a space after the fence\n\n```bash \nls\n```",  # the installed regex takes it; 1.0.0's did not
            reply(FIX, "fix"),
            reply(SUBMIT_1_0_0, "done"),
        ]
    )
    result, records = run(env, client)

    assert (result.end_reason, result.success, result.steps, result.llm_calls, result.json_repairs) == ("success", True, 3, 4, 1)
    defaults = yaml.safe_load((SHIPPED / "agent_defaults.yaml").read_text())["agent"]
    want = {**defaults, **config_1_0_0(), "step_limit": 0, "cost_limit": 3.0}
    assert {k: spied[k] for k in want} == want
    # 1.0.0 rendered with undefined names empty (its {{working_dir}}); its system text was not a template
    agent = config_1_0_0()
    task = Template(agent["instance_template"]).render(task=env.instance.problem_statement)
    assert "- MODIFY: Regular source code files in \n" in task
    first = client.requests[0].messages
    assert [(m.role, m.content) for m in first] == [("system", agent["system_template"]), ("user", task)]
    sent = [(m.role, m.content) for m in client.requests[3].messages[2:]]
    assert sent[1] == ("user", "<returncode>0</returncode>\n<output>\nCOMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT</output>")
    assert sent[3] == ("user", Template(agent["format_error_template"]).render(actions=[]))
    assert [s.action for s in records if isinstance(s, StepRecord)] == [
        "echo COMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT",
        FIX,
        SUBMIT_1_0_0,
    ]
    assert [m.kind for m in records if isinstance(m, MessageRecord)][-2:] == ["reply", "exit"]
    assert env.evaluation is not None and env.evaluation.resolved


def test_the_installed_configuration_still_runs_under_paper(
    swe_env: Callable[..., SweEnvironment], spied: dict[str, Any]
) -> None:
    env = swe_env("offbyone", max_commands=7)
    client = ScriptedClient([reply(f"echo {SENTINEL_1_0_0}"), reply("echo COMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT")])
    result, records = run(env, client, make_agent("mini_swe", profile="paper", benchmark=get_benchmark("swe")))
    assert (result.end_reason, result.steps) == ("agent_done", 2)  # 1.0.0's line is an ordinary command here
    assert spied["step_limit"] == 7 and re.search("COMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT", spied["instance_template"])


def test_the_offline_expert_submits_with_1_0_0s_line(swe_env: Callable[..., SweEnvironment]) -> None:
    env = swe_env("twofiles")
    client = OfflineExpert(env)
    result, records = run(env, client)
    assert (result.end_reason, result.success) == ("success", True)
    assert [s.action for s in records if isinstance(s, StepRecord)][-1] == f"echo {SENTINEL_1_0_0}"
