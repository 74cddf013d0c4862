"""The fake server's fault modes: their names, the bodies and usage blocks they answer with, and the
in-message directive (``FAKE:<mode>[*N]``) that asks for one."""

from __future__ import annotations

import json
import re
from typing import Any

DEFAULT_REPLY = '{"think": "fake server reply", "action": "wait"}'
#: modes of a request that offers ``tools`` (a request without tools gets the plain reply):
#: ``toolcall`` one call of the first tool (or of the one ``tool_choice`` names), ``paralleltools``
#: one call per tool (two calls when there is one tool), ``badargs`` a call whose arguments are
#: cut JSON, ``textinstead`` the plain text reply even when ``tool_choice`` requires a call.
#: Without a directive, ``tool_choice`` "required" or a named tool gets ``toolcall``.
TOOL_MODES = ("toolcall", "paralleltools", "badargs", "textinstead")
#: a hostile provider's tool calls (issue 35 item 6), each an HTTP 200 with the model's reply to a
#: request that offers tools: ``deepargs`` arguments nested :data:`DEEP_LEVELS` levels deep (a JSON
#: string, as OpenAI sends them), ``deepbody`` the same nesting as an object inside the body (no
#: JSON reader of the client gets through it), ``bigargs`` :data:`BIG_ARGS_BYTES` of arguments,
#: ``dupids`` two calls under one id, ``nullfunc`` a call whose ``function`` is null,
#: ``textandcalls`` content and a call together, ``nocalls`` finish reason ``tool_calls`` with no
#: call and null content, ``objargs`` arguments as an object instead of a string, ``bigid`` a call id
#: of :data:`BIG_ID_BYTES`. The completion tokens reported are the reply's, at most ``max_tokens``.
HOSTILE_CALL_MODES = ("deepargs", "deepbody", "bigargs", "dupids", "nullfunc", "textandcalls", "nocalls", "objargs", "bigid")
DEEP_LEVELS = 200_000
BIG_ARGS_BYTES = 5_000_000
BIG_ID_BYTES = 1_000_000
#: the content of ``textandcalls``
TEXT_WITH_CALLS = "Let me look at the files first."
#: stands for the deep object in ``deepbody``'s payload until the body is written
DEEP_PLACEHOLDER = "__FAKE_DEEP_OBJECT__"


def deep_object_text(levels: int = DEEP_LEVELS) -> str:
    """A JSON object nested ``levels`` deep, as text (``json.dumps`` itself cannot write one)."""
    return '{"a": ' * levels + "1" + "}" * levels


def hostile_calls(mode: str, calls: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The calls of a hostile mode, made from the well-formed ones the server would send."""
    first = calls[0]
    function = first["function"]
    if mode == "deepargs":
        function["arguments"] = "[" * DEEP_LEVELS + "]" * DEEP_LEVELS
    elif mode == "deepbody":
        function["arguments"] = DEEP_PLACEHOLDER
    elif mode == "bigargs":
        args = json.loads(function["arguments"])
        key = next((k for k, v in args.items() if isinstance(v, str)), "text")
        args[key] = "x" * BIG_ARGS_BYTES
        function["arguments"] = json.dumps(args)
    elif mode == "dupids":
        calls = [first, {**first, "function": dict(function)}]
    elif mode == "nullfunc":
        first["function"] = None
    elif mode == "objargs":
        function["arguments"] = json.loads(function["arguments"])
    elif mode == "bigid":
        first["id"] = "i" * BIG_ID_BYTES
    elif mode == "nocalls":
        calls = []
    return calls


FAULT_MODES = (
    "429",
    "500",
    "502",
    "503",
    "hang",
    "empty",
    "malformed",
    "ctx",
    "400",
    "401",
    "retrylong",
    "echokey",
    "negusage",
    "zerousage",
    "hugeusage",
    "fracusage",
    "nousage",
    "negcached",
    "notjson",
    "html",
    "textplain",
    "nochoices",
    "nullchoices",
    "nomessage",
    "nullcontent",
    *TOOL_MODES,
    *HOSTILE_CALL_MODES,
)
#: modes answering HTTP 200 with a reply no client can use: a body that is not JSON (``notjson``,
#: ``html``; ``malformed`` cut mid-JSON, ``empty``), or a chat completion without a usable choice
#: (``nochoices``: ``choices: []``, ``nullchoices``: ``choices: null``, ``nomessage``: a choice
#: without ``message``, ``nullcontent``: content null and no tool calls). The provider generated the
#: reply: it bills prompt + completion (the log records the tokens it generated, so tests can
#: compute the bill). ``textplain`` (a good reply under a ``text/plain`` content type) is readable.
UNREADABLE_MODES = ("empty", "malformed", "notjson", "html", "nochoices", "nullchoices", "nomessage", "nullcontent")
#: usage blocks of the lying-provider modes (None: the field is left out)
USAGE_FAULTS: dict[str, dict[str, Any]] = {
    "negusage": {"prompt_tokens": -1_000_000, "completion_tokens": -1_000_000},
    "zerousage": {"prompt_tokens": 0, "completion_tokens": 0},
    "hugeusage": {"prompt_tokens": 50_000_000, "completion_tokens": 50_000_000},
    "fracusage": {"prompt_tokens": 10.5, "completion_tokens": 2.25},
    "nousage": {"prompt_tokens": None, "completion_tokens": None, "cached_tokens": None, "cache_write_tokens": None},
    "negcached": {"cached_tokens": -1_000_000},
}
#: the bodies of the unreadable modes that are not JSON: (bytes, content type)
NOT_JSON_BODIES: dict[str, tuple[bytes, str]] = {
    "empty": (b"", "application/json"),
    "malformed": (b'{"id": "chatcmpl-fake", "choices": [{"mess', "application/json"),
    "notjson": (b"upstream answered: OK", "application/json"),
    "html": (b"<html><head><title>502 Bad Gateway</title></head><body><h1>502 Bad Gateway</h1></body></html>", "text/html"),
}
#: the choices of the unreadable modes whose body is a chat completion
CHOICE_FAULTS: dict[str, Any] = {
    "nochoices": lambda choices: [],
    "nullchoices": lambda choices: None,
    "nomessage": lambda choices: [{"index": c["index"], "finish_reason": c["finish_reason"]} for c in choices],
    "nullcontent": lambda choices: [
        {"index": c["index"], "message": {"role": "assistant", "content": None}, "finish_reason": c["finish_reason"]}
        for c in choices
    ],
}
DIRECTIVE = re.compile(r"FAKE:([a-z0-9]+)(?:\*(\d+))?")


def placeholder_args(parameters: Any) -> dict[str, Any]:
    """Arguments that satisfy a tool's JSON schema's required properties by their type (a string
    property gets "fake"), so a fake call is well formed for the tool that receives it."""
    if not isinstance(parameters, dict):
        return {}
    properties = parameters.get("properties") or {}
    by_type = {"string": "fake", "integer": 0, "number": 0, "boolean": False, "array": [], "object": {}}
    out: dict[str, Any] = {}
    for name in parameters.get("required") or []:
        spec = properties.get(name) or {}
        kind = spec.get("type") if isinstance(spec, dict) else None
        out[str(name)] = by_type.get(str(kind), "fake")
    return out


def error_body(message: str, etype: str, code: str | None, param: str | None = None) -> dict[str, Any]:
    """An error reply in the OpenAI shape."""
    return {"error": {"message": message, "type": etype, "param": param, "code": code}}
