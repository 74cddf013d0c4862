"""Skip the OpenAI SDK's per-message type walk for chat requests whose values are plain JSON.

Why: litellm sends OpenAI and OpenAI-compatible calls through the OpenAI SDK, whose
``chat.completions.create`` walks the whole request against its TypedDicts
(``openai._utils._transform.async_maybe_transform`` over ``CompletionCreateParams``) to apply
key aliases and date/base64 formats. The walk tries every member of the message union on every
message, so it costs CPU in proportion to the conversation: profiled on 10-call ReAct episodes
through the gateway (issue 37) it was about 40 % of the gateway's CPU per call, more than the
rest of litellm and the gateway together, and it grows with each re-sent prefix.

For chat-completion parameters the walk changes nothing a plain-JSON value holds: none of the
types under ``openai.types.chat`` or ``openai.types.shared_params`` declares a key alias or a
format (:func:`chat_params_need_transform` checks that at install time, so an SDK that adds one
keeps the full walk). What the walk does to the rest - drops omitted values, dumps pydantic
models, turns tuples into lists - still happens: only values made of dicts, lists, strings,
numbers, booleans and None are passed through as they are; every other value (and every other
request type) goes through the SDK's own function.
"""

from __future__ import annotations

import importlib
import pkgutil
from typing import Any

_PLAIN_SCALARS = (str, int, float, bool, type(None))
_installed = False


def is_plain_json(value: Any) -> bool:
    """True when ``value`` is made only of dicts with string keys, lists and JSON scalars
    (exact types: a subclass such as a pydantic model or an SDK sentinel is not plain)."""
    stack = [value]
    while stack:
        v = stack.pop()
        t = type(v)
        if t in _PLAIN_SCALARS:
            continue
        if t is dict:
            for k, item in v.items():
                if type(k) is not str:
                    return False
                stack.append(item)
        elif t is list:
            stack.extend(v)
        else:
            return False
    return True


def _declares_transform(hint: Any, property_info: Any) -> bool:
    """True when a type hint carries a ``PropertyInfo`` with an alias or a format (anywhere in
    its ``Annotated``/``Union``/``List`` arguments)."""
    todo = [hint]
    while todo:
        h = todo.pop()
        for meta in getattr(h, "__metadata__", ()):
            if isinstance(meta, property_info) and (meta.alias is not None or meta.format is not None):
                return True
        todo.extend(a for a in getattr(h, "__args__", ()) or () if not isinstance(a, (str, int, float, bool)))
    return False


def chat_params_need_transform() -> bool:
    """True when a request type (a TypedDict) of the installed SDK's chat or shared parameters
    declares a key alias or a format: then the walk can change plain values and must run."""
    import openai.types.chat as chat
    import openai.types.shared_params as shared
    from openai._utils import PropertyInfo
    from openai._utils._transform import get_type_hints
    from typing_extensions import is_typeddict

    for package in (chat, shared):
        for info in pkgutil.iter_modules(package.__path__):
            module = importlib.import_module(f"{package.__name__}.{info.name}")
            for obj in vars(module).values():
                if not is_typeddict(obj):
                    continue
                if any(_declares_transform(h, PropertyInfo) for h in get_type_hints(obj, include_extras=True).values()):
                    return True
    return False


def _split(data: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """(the plain-JSON containers, everything else) of a request body."""
    plain = {k: v for k, v in data.items() if type(v) in (dict, list) and is_plain_json(v)}
    return plain, {k: v for k, v in data.items() if k not in plain}


def _merge(data: dict[str, Any], plain: dict[str, Any], walked: dict[str, Any]) -> dict[str, Any]:
    """The body in the caller's key order: plain values as given, the others as the walk left them
    (the walk drops omitted values)."""
    return {k: plain[k] if k in plain else walked[k] for k in data if k in plain or k in walked}


def make_fast_transform(original: Any, param_types: tuple[Any, ...]) -> Any:
    """``original`` (the SDK's ``async_maybe_transform``) with the plain-JSON values of a chat
    request set aside before the walk and put back after it, unchanged."""

    async def async_maybe_transform(data: Any, expected_type: Any) -> Any:
        if expected_type not in param_types or type(data) is not dict:
            return await original(data, expected_type)
        plain, rest = _split(data)
        return _merge(data, plain, await original(rest, expected_type))

    async_maybe_transform.__wrapped__ = original  # type: ignore[attr-defined]
    return async_maybe_transform


def make_fast_transform_sync(original: Any, param_types: tuple[Any, ...]) -> Any:
    """The same for the SDK's blocking ``maybe_transform`` (the direct client's calls)."""

    def maybe_transform(data: Any, expected_type: Any) -> Any:
        if expected_type not in param_types or type(data) is not dict:
            return original(data, expected_type)
        plain, rest = _split(data)
        return _merge(data, plain, original(rest, expected_type))

    maybe_transform.__wrapped__ = original  # type: ignore[attr-defined]
    return maybe_transform


def install() -> bool:
    """Put the fast path in front of the SDK's chat-completion transform (once per process);
    False (nothing changed) when the SDK's chat types need the walk or its layout differs."""
    global _installed
    if _installed:
        return True
    try:
        from openai.resources.chat.completions import completions as module
        from openai.types.chat import completion_create_params as params
    except ImportError:
        return False
    original = getattr(module, "async_maybe_transform", None)
    original_sync = getattr(module, "maybe_transform", None)
    types = (
        getattr(params, "CompletionCreateParamsNonStreaming", None),
        getattr(params, "CompletionCreateParamsStreaming", None),
    )
    if original is None or original_sync is None or None in types or chat_params_need_transform():
        return False
    module.async_maybe_transform = make_fast_transform(original, types)
    module.maybe_transform = make_fast_transform_sync(original_sync, types)
    _installed = True
    return True
