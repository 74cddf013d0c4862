"""The ``offline/`` litellm custom provider: routes ``offline/<name>`` to a test double.

Why through litellm: a test double must exercise the same code as a real provider (the
gateway's admission, retries, ledger and records, litellm's response objects). Hints reach
the handler in litellm's ``metadata`` (never in the messages); the handler reports usage
like a provider would (counted with the documented chars/4 estimate).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from typing import Any

from recap.baselines.textreply import render as render_text
from workers.llm.offline.expert import expert_reply
from workers.llm.offline.knobs import MALFORMED_JSON, Knobs, OfflineOptionsError, draw
from workers.llm.offline.random_model import random_reply
from workers.llm.offline.replay import ReplayError, replay_index
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
    """The reply text of test double ``name`` (without the ``offline/`` prefix)."""
    meta = dict((metadata or {}).get(METADATA_KEY) or {})
    call_key = str(meta.get("call_key", ""))
    hints = meta.get("hints") or {}
    if name == "replay":
        if not api_base:
            raise ReplayError("offline/replay needs api_base = the run folder to replay")
        return replay_index(api_base).answer(messages, call_key)
    maker = _REPLY_MAKERS.get(name)
    if maker is None:
        raise OfflineOptionsError(f"unknown offline model offline/{name}; known: {', '.join('offline/' + m for m in MODELS)}")
    knobs = Knobs.from_options(meta.get("options"))
    if knobs.malformed_json_rate > 0 and draw(call_key, knobs.noise_seed, "malformed") < knobs.malformed_json_rate:
        return MALFORMED_JSON
    reply = maker(hints, knobs, call_key)
    layout = hints.get("text_layout")
    if layout:  # an agent reading plain text (reply_format: text) names its layout
        return render_text(str(layout), reply)
    return json.dumps(reply)


def _make_provider_class() -> type:
    # litellm only once it is imported offline and quiet (workers.llm.litellm_import)
    from litellm import CustomLLM
    from litellm.llms.custom_llm import CustomLLMError
    from litellm.types.utils import Usage

    class OfflineProvider(CustomLLM):
        """TEST DOUBLE provider for ``offline/expert``, ``offline/random``, ``offline/replay``."""

        def _fill(
            self, model: str, messages: list, api_base: str | None, model_response: Any, litellm_params: Mapping[str, Any] | None
        ) -> Any:
            msgs = [{"role": str(m["role"]), "content": str(m.get("content") or "")} for m in messages]
            try:
                text = offline_text(model, msgs, (litellm_params or {}).get("metadata"), api_base)
            except (ReplayError, OfflineOptionsError, ValueError) as exc:
                raise CustomLLMError(status_code=400, message=str(exc)) from None
            model_response.choices[0].message.content = text
            model_response.choices[0].finish_reason = "stop"
            model_response.model = f"{PROVIDER}/{model}"
            prompt = estimate_prompt_tokens(msgs)
            completion = estimate_text_tokens(text)
            model_response.usage = Usage(prompt_tokens=prompt, completion_tokens=completion, total_tokens=prompt + completion)
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
            return self._fill(model, messages, api_base, model_response, litellm_params)

        async def acompletion(self, *args, **kwargs):  # the same answer, awaited (litellm's async path)
            return self.completion(*args, **kwargs)

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
