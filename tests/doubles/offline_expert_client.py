"""The ``offline/expert`` test double as an in-process LLMClient: the provider's own reply code
(workers.llm.offline.provider.offline_text) fed with the agent's hints plus the environment's
expert plan, as the episode worker adds it, without litellm or a gateway."""

from __future__ import annotations

from recap.env import Environment
from recap.llm import LLMRequest, LLMResponse
from workers.llm.offline.provider import offline_text
from workers.llm.offline.wire import OFFLINE_METADATA_KEY


class OfflineExpert:
    """Answers every request as ``offline/expert`` would for ``env``'s current state."""

    def __init__(self, env: Environment) -> None:
        self.env = env
        self.requests: list[LLMRequest] = []

    def complete(self, request: LLMRequest) -> LLMResponse:
        self.requests.append(request)
        hints = {**request.hints, "expert_plan": self.env.expert_plan()}
        meta = {OFFLINE_METADATA_KEY: {"call_key": request.call_key, "hints": hints, "options": {"seed": 1}}}
        text = offline_text("expert", [], meta, None)
        return LLMResponse(
            text=text,
            model="offline/expert",
            prompt_tokens=1,
            completion_tokens=1,
            cost_usd=0.0,
            token_count_source="estimate",
            served_from="replay",
            test_double=True,
        )
