"""Tool calls in the agent runtime: the history keeps calls and their results together, the
conversation offers tools and hands back the calls, the driver runs them and writes their rows."""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import pytest

from recap.config import AgentConfig
from recap.env import Demonstration, Environment, Reset, Step
from recap.history import History
from recap.jsonreply import ReplyFormatError
from recap.llm import LLMResponse, ToolCall, ToolDef
from recap.runtime import NOT_RUN, Conversation, EnvDriver, EpisodeEnd
from recap.scripted import ScriptedClient
from schemas.records import MessageRecord, StepRecord, ToolCallRecord

BASH = ToolDef("bash", "run one command", {"type": "object", "properties": {"command": {"type": "string"}}})
SUBMIT = ToolDef("submit", "hand in the change")


def _call(i: int, name: str = "bash", arguments: str = '{"command": "ls"}') -> ToolCall:
    return ToolCall.parse(f"call_{i}", name, arguments)


def _reply(text: str, *calls: ToolCall) -> LLMResponse:
    return LLMResponse(text=text, model="scripted", tool_calls=calls, test_double=True)


class ToolEnv(Environment):
    """Two tools: ``bash`` echoes its command (``fail`` is refused), ``submit`` ends the episode."""

    benchmark = "toy"
    max_steps = 5

    def __init__(self) -> None:
        self.ran: list[tuple[str, dict[str, Any]]] = []

    def reset(self) -> Reset:
        return Reset("a repository", None, "fix it")

    def step(self, action: str) -> Step:
        return self.call_tool("bash", {"command": action})

    def tool_defs(self) -> tuple[ToolDef, ...]:
        return (BASH, SUBMIT)

    def call_tool(self, name: str, args: Mapping[str, Any]) -> Step:
        self.ran.append((name, dict(args)))
        if name == "submit":
            return Step("submitted", None, True, True, {})
        if args.get("command") == "fail":
            return Step("error: refused", None, False, False, {"error": "refused", "tool": "bash"})
        info = {"exit_code": 0, "duration_s": 0.25, "output_bytes": 7, "tool": "bash"}
        return Step(f"ran {args['command']}", None, False, False, info)

    def rules(self) -> str:
        return ""

    def demonstration(self) -> Demonstration | None:
        return None


def test_a_reply_and_its_tool_results_are_dropped_together():
    rows: list[MessageRecord] = []
    h = History("e", 4, emit=rows.append)
    h.pin("user", "task", "task")
    h.add("assistant", "reply", "", tool_calls=(_call(0), _call(1)))
    h.add("tool", "tool_result", "out0", tool_call_id="call_0")
    h.add("tool", "tool_result", "out1", tool_call_id="call_1")
    h.add("user", "observation", "next")
    h.add("assistant", "reply", "", tool_calls=(_call(2),))
    h.add("tool", "tool_result", "out2", tool_call_id="call_2")
    # the window (4) overflowed at 6 live messages: the oldest pair went, and the tool result
    # left at the head went with its call
    assert [(m.role, m.content) for m in h.messages()] == [
        ("user", "task"),
        ("user", "next"),
        ("assistant", ""),
        ("tool", "out2"),
    ]
    assert h.messages()[2].tool_calls == (_call(2),)
    assert h.messages()[3].tool_call_id == "call_2"
    assert rows[1].tool_calls == json.dumps(
        [
            {"id": "call_0", "name": "bash", "arguments": '{"command": "ls"}'},
            {"id": "call_1", "name": "bash", "arguments": '{"command": "ls"}'},
        ]
    )
    assert (rows[2].role, rows[2].tool_call_id, rows[2].tool_calls) == ("tool", "call_0", None)
    assert rows[4].tool_calls is None and rows[4].tool_call_id is None


def _conversation(client: ScriptedClient, rows: list[Any]) -> Conversation:
    return Conversation(
        episode_id="e",
        client=client,
        config=AgentConfig(window=20, max_json_repairs=1, json_mode=True),
        style="recap",
        emit=rows.append,
        expected_format='{"think": "...", "subtasks": [...]}',
    )


def _think(obj: dict[str, Any]) -> dict[str, Any]:
    if obj and "think" not in obj:
        raise ReplyFormatError("no think")
    return obj


def test_ask_tools_offers_the_tools_and_returns_the_calls():
    client = ScriptedClient([_reply("", _call(0)), _reply('{"think": "t", "subtasks": []}')])
    rows: list[Any] = []
    conv = _conversation(client, rows)
    parsed, calls, seq = conv.ask_tools("go", "task", _think, tools=(BASH, SUBMIT), tool_choice="auto")
    assert (parsed, calls, seq) == ({}, (_call(0),), 1)
    request = client.requests[0]
    assert request.tools == (BASH, SUBMIT) and request.tool_choice == "auto"
    assert request.json_mode is False  # JSON mode and tools do not go together on the wire
    conv.add_tool_result(calls[0], "listing")
    parsed, calls, _ = conv.ask_tools(None, "task", _think, tools=(BASH,))
    assert (parsed, calls) == ({"think": "t", "subtasks": []}, ())
    assert [(m.role, m.content, m.tool_call_id) for m in client.requests[1].messages] == [
        ("user", "go", None),
        ("assistant", "", None),
        ("tool", "listing", "call_0"),
    ]
    # a plain ask sends no tools
    client2 = ScriptedClient(['{"think": "x"}'])
    _conversation(client2, []).ask("go", "task", _think)
    assert client2.requests[0].tools == () and client2.requests[0].json_mode is True


def test_a_repaired_reply_has_its_calls_answered_as_not_run():
    client = ScriptedClient([_reply("oops", _call(0)), _reply('{"think": "ok"}', _call(1))])
    rows: list[Any] = []
    conv = _conversation(client, rows)
    parsed, calls, _ = conv.ask_tools("go", "task", _think, tools=(BASH,))
    assert (parsed, calls) == ({"think": "ok"}, (_call(1),))
    messages = [m for m in rows if isinstance(m, MessageRecord)]
    assert [(m.role, m.kind, m.content, m.tool_call_id) for m in messages[:3]] == [
        ("user", "task", "go", None),
        ("assistant", "reply", "oops", None),
        ("tool", "tool_result", NOT_RUN, "call_0"),
    ]
    assert messages[3].content.startswith("I could not use your last reply: ")
    kinds = [(m.role, m.kind) for m in rows if isinstance(m, MessageRecord)]
    assert kinds == [
        ("user", "task"),
        ("assistant", "reply"),
        ("tool", "tool_result"),
        ("user", "repair"),
        ("assistant", "reply"),
    ]
    assert conv.usage.json_repairs == 1


def test_the_driver_runs_tool_calls_and_records_each():
    env = ToolEnv()
    rows: list[Any] = []
    driver = EnvDriver(env, "e", rows.append)
    driver.reset()
    step = driver.execute_tool(_call(0), node_id=3, message_seq=7)
    assert step.observation == "ran ls"
    bad = driver.execute_tool(ToolCall.parse("call_1", "bash", '{"command": '), node_id=3, message_seq=7)
    assert bad.observation.startswith("error: arguments are not valid JSON")
    unknown = driver.execute_tool(_call(2, "edit", "{}"), node_id=3, message_seq=9)
    assert unknown.observation == "error: there is no tool named 'edit'; the tools are: bash, submit"
    refused = driver.execute_tool(_call(3, arguments='{"command": "fail"}'), node_id=4, message_seq=9)
    assert refused.observation == "error: refused"
    text = driver.execute("pwd", node_id=5)  # a coding environment's text action: one command
    assert text.observation == "ran pwd"
    assert env.ran == [("bash", {"command": "ls"}), ("bash", {"command": "fail"}), ("bash", {"command": "pwd"})]
    assert (driver.steps, driver.invalid, driver.attempts) == (3, 3, 5)
    tools = [r for r in rows if isinstance(r, ToolCallRecord)]
    assert tools == [
        ToolCallRecord("e", 0, 0, "bash", '{"command": "ls"}', True, "call_0", 7, 3, None, 0, 0.25, 7, False),
        ToolCallRecord("e", 1, 1, "bash", '{"command": ', False, "call_1", 7, 3, bad.info["error"], None, 0.0, 0, False),
        ToolCallRecord(
            "e", 2, 2, "edit", "{}", False, "call_2", 9, 3, "there is no tool named 'edit'; the tools are: bash, submit"
        ),
        ToolCallRecord("e", 3, 3, "bash", '{"command": "fail"}', False, "call_3", 9, 4, "refused"),
        ToolCallRecord("e", 4, 4, "bash", '{"command": "pwd"}', True, None, None, 5, None, 0, 0.25, 7, False),
    ]
    steps = [r for r in rows if isinstance(r, StepRecord)]
    assert [(s.index, s.env_step, s.action, s.valid) for s in steps] == [
        (0, 1, 'bash {"command": "ls"}', True),
        (1, 1, 'bash {"command": ', False),
        (2, 1, "edit {}", False),
        (3, 2, 'bash {"command": "fail"}', False),
        (4, 3, "pwd", True),
    ]
    with pytest.raises(EpisodeEnd) as end:
        driver.execute_tool(_call(5, "submit", ""), node_id=1)
    assert end.value.reason == "success" and driver.success
