"""litellm's reading of a reply's tool calls, made safe for whatever a model writes in them.

Why: litellm turns every HTTP 200 chat completion into its response object through
``convert_to_model_response_object``, which first hands each tool call to
``handle_invalid_parallel_tool_calls`` (litellm/litellm_core_utils/llm_response_utils/
convert_dict_to_response.py:376-416, litellm 1.106): it runs ``json.loads`` on every call's
arguments (catching only ``JSONDecodeError``) and reads ``tool_call.function.name``. Arguments
nested 200,000 levels deep raise ``RecursionError`` there, a call whose ``function`` is null raises
``AttributeError``; either way litellm reports the reply as a 500-class error
("Invalid response object") although the reply arrived, and the call failed as infrastructure
(``server_error``, the unit ``infra_error``, paid again by every resume).

The helper only rewrites OpenAI's hallucinated ``multi_tool_use.parallel`` pseudo-call into its
real calls. :func:`install` wraps it: a reply whose calls it cannot read safely (a call without
a function, arguments that are not a string or nest deeper than
:data:`recap.llm.MAX_ARGUMENT_DEPTH`) keeps its calls as they are, and a ``RecursionError`` inside
it does too. What the calls hold is then judged by :func:`workers.llm.calling.read_tool_calls` and
:meth:`recap.llm.ToolCall.parse`: each is recorded and, when it cannot run, answered as invalid.
"""

from __future__ import annotations

import functools
from typing import Any

from recap.llm import MAX_ARGUMENT_DEPTH, json_depth

#: set on the wrapper, so a second install is a no-op
_MARK = "_recap_guarded"


def _readable(call: Any) -> bool:
    """Whether litellm's helper can read ``call`` without failing on what the model wrote."""
    if type(call).__name__ == "ChatCompletionMessageCustomToolCall":
        return True  # the helper skips custom tool calls
    function = getattr(call, "function", None)
    arguments = getattr(function, "arguments", None)
    return function is not None and isinstance(arguments, str) and json_depth(arguments) <= MAX_ARGUMENT_DEPTH


def guarded(original: Any) -> Any:
    """``original`` (litellm's ``handle_invalid_parallel_tool_calls``) made safe: the calls as
    given when any of them is unsafe to read or reading them recurses too deep."""

    @functools.wraps(original)
    def handle(tool_calls: Any) -> Any:
        if tool_calls is None:
            return None
        if not all(_readable(c) for c in tool_calls):
            return tool_calls
        try:
            return original(tool_calls)
        except RecursionError:
            return tool_calls

    setattr(handle, _MARK, True)
    return handle


def install(litellm: Any) -> None:
    """Wrap litellm's tool-call helper where the response conversion looks it up (idempotent)."""
    del litellm  # imported: the module below is loaded with it
    from litellm.litellm_core_utils.llm_response_utils import convert_dict_to_response as module

    current = module.handle_invalid_parallel_tool_calls
    if not getattr(current, _MARK, False):
        module.handle_invalid_parallel_tool_calls = guarded(current)
