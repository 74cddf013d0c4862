"""Tool calls on the wire: LLMRequest tools through the real litellm client to the fake server and back."""

from __future__ import annotations

import pytest

from recap.llm import ChatMessage, LLMRequest, ToolCall, ToolDef
from workers.llm.direct import LiteLLMClient
from workers.llm.offline.fake_server import DEFAULT_REPLY
from workers.llm.providers import DeploymentConfig
from workers.llm.tokens import TOKENS_PER_TOOL, estimate_text_tokens, tools_text

BASH = ToolDef(
    "bash",
    "run one shell command",
    {"type": "object", "properties": {"command": {"type": "string"}}, "required": ["command"]},
)
VIEW = ToolDef(
    "view",
    "show a file",
    {"type": "object", "properties": {"path": {"type": "string"}, "line": {"type": "integer"}}, "required": ["path", "line"]},
)


def _request(content: str, tools=(BASH, VIEW), tool_choice: str | None = "auto", history=()) -> LLMRequest:
    return LLMRequest(
        messages=(*history, ChatMessage("user", content)),
        episode_id="ep",
        call_index=0,
        purpose="task",
        tools=tuple(tools),
        tool_choice=tool_choice,
    )


@pytest.fixture
def client_and_server(fake_server):
    server = fake_server(keep_bodies=True)
    records = []
    client = LiteLLMClient(
        DeploymentConfig(model="openai/fake-gpt", api_base=server.base_url, max_attempts=1, params={"max_tokens": 50}),
        record_sink=records.append,
    )
    return client, server, records


def test_one_tool_call_comes_back_parsed_with_usage(client_and_server):
    client, server, records = client_and_server
    resp = client.complete(_request("FAKE:toolcall"))
    assert resp.tool_calls == (ToolCall("call_fake_1_0", "bash", '{"command": "fake"}', {"command": "fake"}, None),)
    assert (resp.text, resp.finish_reason) == ("", "tool_calls")
    # prompt: 3 + 3 + ceil(13/4) = 10; completion: ceil(len('bash{"command": "fake"}') / 4) = 6
    # the provider bills the tool definitions it was sent: the messages' 10 tokens, the tools' JSON
    # at ceil(chars / 4) and a framing allowance per tool
    tools = 10 + estimate_text_tokens(tools_text([BASH.as_dict(), VIEW.as_dict()])) + 2 * TOKENS_PER_TOOL
    assert tools == 131
    assert (resp.prompt_tokens, resp.completion_tokens, resp.token_count_source) == (tools, 6, "provider")
    assert resp.cost_usd == (tools * 1 + 6 * 2) / 1e6
    assert [(r.status, r.prompt_tokens, r.completion_tokens) for r in records] == [("ok", tools, 6)]
    body = server.bodies[0]
    assert body["tools"] == [BASH.as_dict(), VIEW.as_dict()]
    assert body["tools"][0] == {
        "type": "function",
        "function": {
            "name": "bash",
            "description": "run one shell command",
            "parameters": {"type": "object", "properties": {"command": {"type": "string"}}, "required": ["command"]},
        },
    }
    assert body["tool_choice"] == "auto"
    assert [c.mode for c in server.log] == ["toolcall"]


def test_parallel_tool_calls_keep_their_order(client_and_server):
    client, _, _ = client_and_server
    resp = client.complete(_request("FAKE:paralleltools"))
    assert [(c.id, c.name, c.args) for c in resp.tool_calls] == [
        ("call_fake_1_0", "bash", {"command": "fake"}),
        ("call_fake_1_1", "view", {"path": "fake", "line": 0}),
    ]


def test_malformed_arguments_are_a_parse_error_not_a_crash(client_and_server):
    client, _, records = client_and_server
    resp = client.complete(_request("FAKE:badargs"))
    (call,) = resp.tool_calls
    assert (call.name, call.arguments, call.args) == ("bash", '{"command": "fake"', None)
    assert call.parse_error is not None and call.parse_error.startswith("arguments are not valid JSON: ")
    assert [r.status for r in records] == ["ok"]


def test_text_although_a_tool_was_required(client_and_server):
    client, server, _ = client_and_server
    resp = client.complete(_request("FAKE:textinstead", tool_choice="required"))
    assert (resp.text, resp.tool_calls, resp.finish_reason) == (DEFAULT_REPLY, (), "stop")
    assert server.bodies[0]["tool_choice"] == "required"


def test_required_or_named_tool_choice_gets_a_call_without_a_directive(client_and_server):
    client, server, _ = client_and_server
    named = client.complete(_request("look at it", tool_choice="view"))
    assert [(c.name, c.args) for c in named.tool_calls] == [("view", {"path": "fake", "line": 0})]
    assert server.bodies[0]["tool_choice"] == {"type": "function", "function": {"name": "view"}}
    required = client.complete(_request("go", tool_choice="required"))
    assert [c.name for c in required.tool_calls] == ["bash"]
    auto = client.complete(_request("go"))
    assert (auto.text, auto.tool_calls) == (DEFAULT_REPLY, ())
    none = client.complete(_request("FAKE:toolcall", tool_choice="none"))
    assert (none.text, none.tool_calls) == (DEFAULT_REPLY, ())


def test_tool_results_go_back_in_the_openai_shape(client_and_server):
    client, server, _ = client_and_server
    call = ToolCall.parse("call_1", "bash", '{"command": "ls"}')
    history = (
        ChatMessage("user", "list the files"),
        ChatMessage("assistant", "", tool_calls=(call,)),
        ChatMessage("tool", "a.py\nb.py", tool_call_id="call_1"),
    )
    client.complete(_request("and now?", history=history))
    assert server.bodies[0]["messages"][1:3] == [
        {
            "role": "assistant",
            "content": "",
            "tool_calls": [{"id": "call_1", "type": "function", "function": {"name": "bash", "arguments": '{"command": "ls"}'}}],
        },
        {"role": "tool", "content": "a.py\nb.py", "tool_call_id": "call_1"},
    ]


def test_a_request_without_tools_sends_nothing_tool_related(client_and_server):
    client, server, _ = client_and_server
    resp = client.complete(_request("FAKE:toolcall", tools=(), tool_choice=None))
    assert (resp.text, resp.tool_calls) == (DEFAULT_REPLY, ())
    assert "tools" not in server.bodies[0] and "tool_choice" not in server.bodies[0]


def test_tool_call_parsing_and_message_rules():
    assert ToolCall.parse("c", "bash", "[1]").parse_error == "arguments are not a JSON object but list"
    assert ToolCall.parse("c", "bash", "").args == {}
    with pytest.raises(ValueError, match="a tool message needs the tool_call_id it answers"):
        ChatMessage("tool", "out")
    with pytest.raises(ValueError, match="only an assistant message carries tool calls, not 'user'"):
        ChatMessage("user", "x", tool_calls=(ToolCall.parse("c", "bash", "{}"),))
    with pytest.raises(ValueError, match="tool_choice 'grep' is none of"):
        _request("x", tool_choice="grep")
    with pytest.raises(ValueError, match="tool_choice is set but the request has no tools"):
        _request("x", tools=(), tool_choice="auto")


SCHEMA = {
    "name": "ReCAP",
    "schema": {
        "type": "object",
        "properties": {"subtasks": {"type": "array", "items": {"type": "string"}}},
        "required": ["subtasks"],
        "additionalProperties": False,
    },
}


@pytest.mark.parametrize(
    ("model", "sent"),
    [
        # a model with strict structured output gets the schema (issue 34: ReCAP's reply_schema)
        ("openai/gpt-4.1", {"type": "json_schema", "json_schema": {**SCHEMA, "strict": True}}),
        # one litellm knows only JSON mode for gets plain JSON
        ("openai/fake-gpt", {"type": "json_object"}),
    ],
)
def test_a_reply_schema_goes_out_as_the_models_strongest_json_format(fake_server, model, sent):
    server = fake_server(keep_bodies=True)
    client = LiteLLMClient(DeploymentConfig(model=model, api_base=server.base_url, max_attempts=1, params={"max_tokens": 50}))
    request = _request("go")
    client.complete(LLMRequest(**{**request.__dict__, "response_schema": SCHEMA}))
    assert server.bodies[0]["response_format"] == sent
    client.complete(request)  # no schema: no response format (tools and plain JSON text, as before)
    assert "response_format" not in server.bodies[1]


def test_no_response_format_where_the_model_has_none_or_for_a_test_double():
    assert DeploymentConfig(model="nosuch/model").schema_params(SCHEMA) == {}
    assert DeploymentConfig(model="offline/expert").schema_params(SCHEMA) == {}
    assert DeploymentConfig(model="openai/gpt-4.1").schema_params(None) == {}
    own = {"response_format": {"type": "text"}}
    assert DeploymentConfig(model="openai/gpt-4.1", params=own).schema_params(SCHEMA) == {}
