"""The offline expert on coding environments (workers/llm/offline/expert_tools.py): it solves the toy
repository with ReCAP's tool-call mode and with ReAct as mini-SWE-agent, through the real litellm
offline provider and the episode worker's client (which attaches the expert plan)."""

from __future__ import annotations

import json
from typing import Any

import pytest

from recap.baselines.react import ReActAgent, ReActConfig
from recap.config import ReCAPConfig
from recap.recap_agent import ReCAPAgent
from schemas.records import MessageRecord, NodeRecord, ToolCallRecord
from tests.recap.toy_repo import BUGGY, FIXED, TEST_CMD, ToyRepo
from workers.episode_worker import EpisodeClient
from workers.llm.direct import LiteLLMClient
from workers.llm.offline.expert_tools import bash_command, bash_plan, tool_reply, work_groups
from workers.llm.offline.provider import offline_reply
from workers.llm.offline.wire import OFFLINE_METADATA_KEY
from workers.llm.providers import DeploymentConfig


def _client(env: ToyRepo) -> EpisodeClient:
    inner = LiteLLMClient(DeploymentConfig(model="offline/expert", offline_options={"seed": 1}))
    return EpisodeClient(inner, env, sampling_seed=0, offline=True)


def test_the_expert_solves_the_toy_repository_with_recap_tool_calls():
    env, rows = ToyRepo(), []
    result = ReCAPAgent(ReCAPConfig(window=100)).run(env, _client(env), episode_id="e", emit=rows.append)
    assert (result.end_reason, result.success, result.steps, result.invalid_actions) == ("success", True, 5, 0)
    assert env.files["app.py"] == FIXED
    assert [c[0] for c in env.calls] == ["view", "str_replace", "bash", "submit", "submit"]
    calls = [r for r in rows if isinstance(r, ToolCallRecord)]
    # one call per reply, named by the call's index
    assert [(c.name, c.call_id) for c in calls] == [
        ("view", "call_1"),
        ("str_replace", "call_4"),
        ("bash", "call_7"),
        ("submit", "call_11"),
        ("submit", "call_12"),
    ]
    nodes = {n.node_id: n for n in rows if isinstance(n, NodeRecord)}
    assert [(n.task, n.depth, n.kind) for n in nodes.values()] == [
        ("review and submit", 0, "root"),
        ("Fix the issue in the repository.", 1, "composite"),
        ("inspect the code", 2, "primitive"),
        ("change the code", 2, "primitive"),
        ("run commands", 2, "primitive"),
        ("submit", 1, "primitive"),
    ]
    assert nodes[1].versions[0].subtasks == ("inspect the code", "change the code", "run commands")
    kinds = [m.kind for m in rows if isinstance(m, MessageRecord) and m.role != "assistant"]
    assert kinds == ["task"] + ["descend", "tool_result", "return"] * 3 + ["return", "descend", "tool_result"]
    assert result.max_depth == 2


def test_the_expert_solves_the_toy_repository_with_mini_swe_react():
    env, rows = ToyRepo(), []
    result = ReActAgent(ReActConfig(window=100)).run(env, _client(env), episode_id="e", emit=rows.append)
    assert (result.end_reason, result.success, result.steps, result.json_repairs) == ("success", True, 4, 0)
    assert env.files["app.py"] == FIXED
    commands = [c[1]["command"] for c in env.calls]
    assert commands[0] == 'cat -n "app.py"' and commands[2:] == [TEST_CMD, "echo COMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT"]
    replies = [m.content for m in rows if isinstance(m, MessageRecord) and m.role == "assistant"]
    assert replies[0] == 'THOUGHT: Expert plan: 4 action(s) left.\n\n```bash\ncat -n "app.py"\n```'


def test_bash_equivalents_of_the_tools():
    assert bash_command({"name": "view", "arguments": {"path": "a b.py"}}) == 'cat -n "a b.py"'
    assert bash_command({"name": "view", "arguments": {"path": "a.py", "view_range": [3, -1]}}) == "sed -n '3,$p' \"a.py\""
    assert bash_command({"name": "submit", "arguments": {}}) == "echo COMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT"
    edit = bash_command({"name": "str_replace", "arguments": {"path": "x.py", "old_str": 'a\'\n"EOF"', "new_str": "é"}})
    assert edit == (
        'python3 - <<\'EOF\'\nimport pathlib\np = pathlib.Path("x.py")\nold = "a\'\\n\\"EOF\\""\nnew = "\\u00e9"\n'
        'text = p.read_text()\nassert text.count(old) == 1, "the text to replace does not occur exactly once"\n'
        "p.write_text(text.replace(old, new, 1))\nEOF"
    )
    with pytest.raises(ValueError, match="no bash equivalent of the tool 'paint'"):
        bash_command({"name": "paint", "arguments": {}})


def test_the_edit_script_runs_in_a_real_shell(tmp_path):
    import subprocess

    (tmp_path / "x.py").write_text(BUGGY)
    cmd = bash_command({"name": "str_replace", "arguments": {"path": "x.py", "old_str": "a - b", "new_str": "a + b  # 'EOF' é"}})
    proc = subprocess.run(["bash", "-c", cmd], cwd=tmp_path, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "x.py").read_text() == "def add(a, b):\n    return a + b  # 'EOF' é\n"
    again = subprocess.run(["bash", "-c", cmd], cwd=tmp_path, capture_output=True, text=True, check=False)
    assert again.returncode == 1 and "does not occur exactly once" in again.stderr


def _plan(*calls: dict[str, Any]) -> list[str]:
    return [json.dumps(c) for c in calls]


VIEW = {"name": "view", "arguments": {"path": "a.py"}}
EDIT = {"name": "str_replace", "arguments": {"path": "a.py", "old_str": "x", "new_str": "y"}}
SUBMIT = {"name": "submit", "arguments": {}}


def test_tool_replies_follow_the_tree():
    hints = {"expert_plan": _plan(VIEW, EDIT, VIEW, SUBMIT, SUBMIT), "task": "goal", "is_root": True}
    assert json.loads(tool_reply(hints, "e#0").text)["subtasks"] == ["inspect the code", "change the code", "inspect the code"]
    node = {**hints, "is_root": False, "task": "inspect the code"}
    answer = tool_reply(node, "e#3")
    assert (answer.text, answer.tool_calls) == (
        "",
        ({"id": "call_3", "name": "view", "arguments": json.dumps(VIEW["arguments"])},),
    )
    wrong = {**node, "task": "change the code"}
    assert json.loads(tool_reply(wrong, "e#4").text) == {"think": "Nothing left for 'change the code'.", "subtasks": []}
    pre = {"expert_plan": _plan(SUBMIT), "task": "review and submit", "is_pre_root": True}
    assert json.loads(tool_reply(pre, "e#5").text)["subtasks"] == ["submit"]
    sub = {"expert_plan": _plan(SUBMIT), "task": "submit", "is_root": False}
    assert tool_reply(sub, "e#6").tool_calls[0]["name"] == "submit"
    assert json.loads(tool_reply({**pre, "expert_plan": None}, "e#7").text)["subtasks"] == []
    assert work_groups([VIEW, VIEW, EDIT, {"name": "bash", "arguments": {}}]) == [
        "inspect the code",
        "change the code",
        "run commands",
    ]
    assert bash_plan({"expert_plan": _plan(VIEW, SUBMIT, SUBMIT)}) == [
        'cat -n "a.py"',
        "echo COMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT",
    ]


def test_the_provider_answers_with_tool_calls_only_when_tools_are_offered():
    meta = {OFFLINE_METADATA_KEY: {"call_key": "e#2", "hints": {"expert_plan": _plan(VIEW), "task": "x"}, "options": {"seed": 1}}}
    with_tools = offline_reply("expert", [], meta, None, ("view",))
    assert with_tools.tool_calls == ({"id": "call_2", "name": "view", "arguments": json.dumps(VIEW["arguments"])},)
    plain = offline_reply("expert", [], meta, None)
    assert plain.tool_calls == () and json.loads(plain.text)["think"] == "Expert plan: 1 action(s) left."
