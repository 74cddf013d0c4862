"""The OpenAI SDK fast path (:mod:`workers.llm.sdk_fast_path`) sends exactly the body the SDK's own
walk would: compared value for value, key order included, on the request shapes our gateway sends
(a growing ReAct conversation, tool calls and tool results, content parts, tools, response format)
and on values the walk must still handle (omitted values, tuples, a pydantic model)."""

from __future__ import annotations

import asyncio
import json

import pydantic
import pytest

from workers.llm import sdk_fast_path
from workers.llm.litellm_setup import get_litellm

get_litellm()  # installs the fast path as every calling process does

from openai import omit  # noqa: E402
from openai._utils import async_maybe_transform, maybe_transform  # noqa: E402  (the SDK's own)
from openai.resources.chat.completions import completions as sdk_module  # noqa: E402
from openai.types.chat import completion_create_params as params  # noqa: E402

NON_STREAMING = params.CompletionCreateParamsNonStreaming

REACT = [
    {"role": "system", "content": "You act in a blocks world."},
    {"role": "user", "content": "Observation: b1 is on the table."},
    {"role": "assistant", "content": "Thought: pick it.\nAction: pickup b1"},
    {"role": "user", "content": "Observation: you hold b1."},
]
TOOLS_TURN = [
    {"role": "user", "content": [{"type": "text", "text": "look"}, {"type": "image_url", "image_url": {"url": "data:,"}}]},
    {
        "role": "assistant",
        "content": None,
        "tool_calls": [{"id": "c1", "type": "function", "function": {"name": "look", "arguments": '{"at": "table"}'}}],
    },
    {"role": "tool", "tool_call_id": "c1", "content": "a table"},
]
TOOLS = [
    {"type": "function", "function": {"name": "look", "parameters": {"type": "object", "properties": {"at": {"type": "string"}}}}}
]


class Note(pydantic.BaseModel):
    role: str = "user"
    content: str = "from a model"


def bodies() -> list[dict]:
    return [
        {"messages": REACT, "model": "gpt-x", "max_tokens": 60, "temperature": 0.0, "tools": omit, "stop": omit},
        {"messages": REACT + TOOLS_TURN, "model": "gpt-x", "tools": TOOLS, "tool_choice": "auto", "n": 1},
        {
            "messages": REACT,
            "model": "gpt-x",
            "response_format": {"type": "json_schema", "json_schema": {"name": "a", "schema": {"type": "object"}}},
            "stop": ["\n"],
        },
        {"messages": tuple(REACT), "model": "gpt-x", "metadata": {"k": "v"}},  # a tuple: the walk makes a list
        {
            "messages": [*REACT, Note(role="user", content="from a model")],
            "model": "gpt-x",
        },  # a pydantic message: the walk dumps it
    ]


def test_the_fast_path_is_installed_for_chat_completions() -> None:
    assert sdk_fast_path.install() is True
    assert sdk_module.async_maybe_transform.__wrapped__ is async_maybe_transform
    assert sdk_module.maybe_transform.__wrapped__ is maybe_transform
    assert sdk_fast_path.chat_params_need_transform() is False


@pytest.mark.parametrize("i", range(5))
def test_fast_body_equals_the_sdk_walk(i: int) -> None:
    body = bodies()[i]
    want = asyncio.run(async_maybe_transform(dict(body), NON_STREAMING))
    got = asyncio.run(sdk_module.async_maybe_transform(dict(body), NON_STREAMING))
    assert got == want
    assert list(got) == list(want)  # same keys in the same order: the same JSON body
    assert json.dumps(got) == json.dumps(want)
    got_sync = sdk_module.maybe_transform(dict(body), NON_STREAMING)
    assert json.dumps(got_sync) == json.dumps(maybe_transform(dict(body), NON_STREAMING))


def test_plain_values_pass_through_and_others_are_walked() -> None:
    body = bodies()[0]
    got = asyncio.run(sdk_module.async_maybe_transform(dict(body), NON_STREAMING))
    assert got["messages"] is REACT  # handed on as given, never walked
    assert "tools" not in got and "stop" not in got  # omitted values still dropped
    tupled = asyncio.run(sdk_module.async_maybe_transform(dict(bodies()[3]), NON_STREAMING))
    assert tupled["messages"] == REACT and type(tupled["messages"]) is list
    dumped = asyncio.run(sdk_module.async_maybe_transform(dict(bodies()[4]), NON_STREAMING))
    assert dumped["messages"][-1] == {"role": "user", "content": "from a model"}


def test_other_request_types_keep_the_full_walk() -> None:
    from openai.types.chat import completion_update_params

    data = {"metadata": {"k": "v"}}
    assert asyncio.run(sdk_module.async_maybe_transform(data, completion_update_params.CompletionUpdateParams)) == data


def test_is_plain_json() -> None:
    assert sdk_fast_path.is_plain_json({"a": [1, 2.5, "x", None, True, {"b": []}]})
    assert not sdk_fast_path.is_plain_json({"a": (1,)})
    assert not sdk_fast_path.is_plain_json({1: "x"})
    assert not sdk_fast_path.is_plain_json([Note()])
    assert not sdk_fast_path.is_plain_json({"a": omit})


def test_an_sdk_type_with_an_alias_keeps_the_walk() -> None:
    from typing import Annotated

    from openai._utils import PropertyInfo

    assert sdk_fast_path._declares_transform(list[Annotated[str, PropertyInfo(alias="cardID")]] | None, PropertyInfo)
    assert sdk_fast_path._declares_transform(Annotated[str, PropertyInfo(format="iso8601")], PropertyInfo)
    assert not sdk_fast_path._declares_transform(Annotated[str, PropertyInfo(discriminator="type")], PropertyInfo)
