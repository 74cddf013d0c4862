"""Token accounting with tools in the prompt: the count, the upper bound and the plausibility check
include the tool definitions and the assistant's tool calls a provider bills, so an honest
provider's usage of a tool request is never rejected as impossible and the reservation still
covers it."""

from __future__ import annotations

import json

from recap.llm import ChatMessage, ToolCall, ToolDef
from workers.llm.accounting import size_request, usage_problems
from workers.llm.calling import Attempt
from workers.llm.tokens import BOUND_TOKENS_PER_TOOL, TOKENS_PER_TOOL, count_prompt_tokens, estimate_text_tokens, tools_text

EDITOR = ToolDef(
    "str_replace",
    "Replace the one occurrence of old_str in a file by new_str. " * 20,
    {"type": "object", "properties": {"path": {"type": "string"}, "old_str": {"type": "string"}, "new_str": {"type": "string"}}},
)
TOOLS = [EDITOR.as_dict(), ToolDef("submit", "hand in the change").as_dict()]
CALL = ToolCall.parse("call_7", "str_replace", json.dumps({"path": "a.py", "old_str": "x = 1" * 40, "new_str": "x = 2"}))
MESSAGES = [
    ChatMessage("user", "fix the bug").as_dict(),
    ChatMessage("assistant", "", tool_calls=(CALL,)).as_dict(),
    ChatMessage("tool", "done", tool_call_id="call_7").as_dict(),
]
MODEL = "openai/some-self-hosted-model"  # no bundled tokenizer: the estimate


def test_the_count_includes_tool_definitions_and_tool_calls():
    plain = count_prompt_tokens(MODEL, [ChatMessage("user", "fix the bug").as_dict()])
    with_calls = count_prompt_tokens(MODEL, MESSAGES)
    with_tools = count_prompt_tokens(MODEL, MESSAGES, TOOLS)
    # the assistant's call (its id, name and arguments) is billed text
    call_text = "\n".join(["call_7", "str_replace", CALL.arguments])
    assert with_calls.tokens == plain.tokens + (3 + estimate_text_tokens(call_text)) + (3 + estimate_text_tokens("done\ncall_7"))
    assert with_tools.tokens == with_calls.tokens + estimate_text_tokens(tools_text(TOOLS)) + 2 * TOKENS_PER_TOOL


def test_the_bound_covers_the_tools_and_an_honest_usage_is_plausible():
    params = {"max_tokens": 100, "tools": TOOLS}
    sized = size_request(MODEL, MESSAGES, params)
    bare = size_request(MODEL, MESSAGES, {"max_tokens": 100})
    assert sized.prompt_bound - bare.prompt_bound == len(tools_text(TOOLS).encode()) + 2 * BOUND_TOKENS_PER_TOOL
    # a provider that bills the tools' rendering (more than our count, under one token per byte)
    billed = sized.counted.tokens + 150
    assert billed > bare.prompt_bound  # without the tools in the bound this honest usage would be "impossible"
    attempt = Attempt(
        text="",
        finish_reason="tool_calls",
        prompt_tokens=billed,
        cached_prompt_tokens=0,
        completion_tokens=12,
        litellm_cost_usd=None,
    )
    assert usage_problems(attempt, sized, 12) == []
    assert usage_problems(attempt, bare, 12) == [f"prompt_tokens {billed} above our upper bound {bare.prompt_bound}"]
