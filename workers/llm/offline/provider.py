"""The ``offline/`` litellm custom provider: routes ``offline/<name>`` to a test double.

Why through litellm: a test double must exercise the same code as a real provider (the
gateway's admission, retries, ledger and records, litellm's response objects). Hints reach
the handler in litellm's ``metadata`` (never in the messages); the handler reports usage
like a provider would (counted with the documented chars/4 estimate).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from recap.baselines.textreply import render as render_text
from workers.llm.offline.expert import expert_reply
from workers.llm.offline.expert_tools import BASH_BLOCK, ToolAnswer, bash_plan, render_bash_block, tool_reply
from workers.llm.offline.knobs import MALFORMED_JSON, Knobs, OfflineOptionsError, draw
from workers.llm.offline.random_model import random_reply
from workers.llm.offline.remote import RemoteError, forward, is_served, request_body
from workers.llm.offline.replay import ReplayError, replay_index
from workers.llm.offline.transcript import is_transcript, transcript_index
from workers.llm.offline.wire import OFFLINE_METADATA_KEY
from workers.llm.tokens import estimate_prompt_tokens, estimate_text_tokens

PROVIDER = "offline"
METADATA_KEY = OFFLINE_METADATA_KEY

_REPLY_MAKERS: dict[str, Callable[[Mapping[str, Any], Knobs, str], dict[str, Any]]] = {
    "expert": expert_reply,
    "random": random_reply,
}
MODELS = ("expert", "random", "replay")


def offline_text(name: str, messages: list[dict[str, str]], metadata: Mapping[str, Any] | None, api_base: str | None) -> str:
    """The reply text of test double ``name`` (without the ``offline/`` prefix) to a request
    without tools."""
    return offline_reply(name, messages, metadata, api_base).text


def offline_reply(
    name: str,
    messages: list[dict[str, str]],
    metadata: Mapping[str, Any] | None,
    api_base: str | None,
    tools: Sequence[str] = (),
    stop: Sequence[str] = (),
) -> ToolAnswer:
    """The reply of test double ``name`` (without the ``offline/`` prefix): its text and, for
    ``offline/expert`` asked with ``tools`` (the offered tools' names), its tool calls
    (:mod:`workers.llm.offline.expert_tools`); ``offline/replay`` of a transcript file matches
    the request's ``stop`` list too (:mod:`workers.llm.offline.transcript`)."""
    meta = dict((metadata or {}).get(METADATA_KEY) or {})
    call_key = str(meta.get("call_key", ""))
    hints = meta.get("hints") or {}
    if name == "replay":
        if not api_base:
            raise ReplayError("offline/replay needs api_base = the run folder to replay")
        if is_transcript(api_base):
            return ToolAnswer(transcript_index(api_base).answer(messages, stop))
        return ToolAnswer(replay_index(api_base).answer(messages, call_key))
    maker = _REPLY_MAKERS.get(name)
    if maker is None:
        raise OfflineOptionsError(f"unknown offline model offline/{name}; known: {', '.join('offline/' + m for m in MODELS)}")
    knobs = Knobs.from_options(meta.get("options"))
    if knobs.malformed_json_rate > 0 and draw(call_key, knobs.noise_seed, "malformed") < knobs.malformed_json_rate:
        return ToolAnswer(MALFORMED_JSON)
    if tools and name == "expert":  # a coding environment's tools: the gold patch's play as calls
        return tool_reply(hints, call_key)
    layout = hints.get("text_layout")
    if layout == BASH_BLOCK:  # one bash command per turn (mini-SWE-agent): the plan's bash equivalents
        hints = {**hints, "expert_plan": bash_plan(hints)}
        return ToolAnswer(render_bash_block(maker(hints, knobs, call_key)))
    reply = maker(hints, knobs, call_key)
    if layout:  # an agent reading plain text (reply_format: text) names its layout
        return ToolAnswer(render_text(str(layout), reply))
    return ToolAnswer(json.dumps(reply))


def tool_names(optional_params: Mapping[str, Any] | None) -> tuple[str, ...]:
    """The names of the tools a litellm call offers (its ``tools`` in the OpenAI shape)."""
    names = []
    for tool in (optional_params or {}).get("tools") or ():
        function = tool.get("function") if isinstance(tool, Mapping) else None
        if isinstance(function, Mapping) and function.get("name"):
            names.append(str(function["name"]))
    return tuple(names)


def stop_list(optional_params: Mapping[str, Any] | None) -> tuple[str, ...]:
    """The stop sequences a litellm call carries (a string or a list; none: empty)."""
    stop = (optional_params or {}).get("stop")
    if stop is None:
        return ()
    return (stop,) if isinstance(stop, str) else tuple(str(s) for s in stop)


def _make_provider_class() -> type:
    # litellm only once it is imported offline and quiet (workers.llm.litellm_import)
    from litellm import CustomLLM
    from litellm.llms.custom_llm import CustomLLMError
    from litellm.types.utils import ChatCompletionMessageToolCall, Function, PromptTokensDetailsWrapper, Usage

    class OfflineProvider(CustomLLM):
        """TEST DOUBLE provider for ``offline/expert``, ``offline/random``, ``offline/replay``."""

        def _fill(
            self,
            model: str,
            messages: list,
            api_base: str | None,
            model_response: Any,
            litellm_params: Mapping[str, Any] | None,
            optional_params: Mapping[str, Any] | None = None,
        ) -> Any:
            msgs = [{"role": str(m["role"]), "content": str(m.get("content") or "")} for m in messages]
            try:
                answer = offline_reply(
                    model,
                    msgs,
                    (litellm_params or {}).get("metadata"),
                    api_base,
                    tool_names(optional_params),
                    stop_list(optional_params),
                )
            except (ReplayError, OfflineOptionsError, ValueError) as exc:
                raise CustomLLMError(status_code=400, message=str(exc)) from None
            prompt = estimate_prompt_tokens(msgs)
            completion = estimate_text_tokens(answer.text + "".join(c["name"] + c["arguments"] for c in answer.tool_calls))
            return self._respond(model, model_response, answer, prompt, completion)

        def _respond(
            self, model: str, model_response: Any, answer: ToolAnswer, prompt: int, completion: int, cached: int = 0
        ) -> Any:
            text = answer.text
            message = model_response.choices[0].message
            message.content = text
            model_response.choices[0].finish_reason = "stop"
            if answer.tool_calls:  # as a provider sends them: OpenAI-shaped calls, finish reason tool_calls
                message.tool_calls = [
                    ChatCompletionMessageToolCall(
                        id=c["id"], type="function", function=Function(name=c["name"], arguments=c["arguments"])
                    )
                    for c in answer.tool_calls
                ]
                model_response.choices[0].finish_reason = "tool_calls"
            model_response.model = f"{PROVIDER}/{model}"
            model_response.usage = Usage(prompt_tokens=prompt, completion_tokens=completion, total_tokens=prompt + completion)
            if cached:  # a served copy's prefix cache hit, as vLLM reports it
                model_response.usage.prompt_tokens_details = PromptTokensDetailsWrapper(cached_tokens=cached)
            return model_response

        def completion(
            self,
            model,
            messages,
            api_base,
            custom_prompt_dict,
            model_response,
            print_verbose,
            encoding,
            api_key,
            logging_obj,
            optional_params,
            acompletion=None,
            litellm_params=None,
            logger_fn=None,
            headers={},  # noqa: B006  (never mutated)
            timeout=None,
            client=None,
        ):  # litellm's CustomLLM signature; litellm passes every argument by keyword
            return self._fill(model, messages, api_base, model_response, litellm_params, optional_params)

        async def acompletion(self, *args, **kwargs):  # the same answer, awaited (litellm's async path)
            if is_served(kwargs.get("api_base")):  # a served copy (serve: {engine: test-double}): over HTTP
                return await self._served(**kwargs)
            return self.completion(*args, **kwargs)

        async def _served(
            self, *, model, messages, api_base, model_response, optional_params, litellm_params=None, timeout=None, **_
        ):
            body = request_body(model, messages, (litellm_params or {}).get("metadata"), optional_params)
            try:
                got = await forward(api_base, body, timeout if isinstance(timeout, (int, float)) else None)
            except RemoteError as exc:
                raise CustomLLMError(status_code=exc.status_code, message=exc.message) from None
            return self._respond(model, model_response, got.answer, got.prompt_tokens, got.completion_tokens, got.cached_tokens)

    return OfflineProvider


def register_offline_provider(litellm: Any) -> None:
    """Add the ``offline`` provider to litellm's custom provider map (idempotent)."""
    if any(item.get("provider") == PROVIDER for item in litellm.custom_provider_map):
        return
    litellm.custom_provider_map = list(litellm.custom_provider_map) + [
        {"provider": PROVIDER, "custom_handler": _make_provider_class()()}
    ]
    from litellm.utils import custom_llm_setup  # litellm is imported by now (see above)

    custom_llm_setup()
