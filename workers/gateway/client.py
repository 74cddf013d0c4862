"""``GatewayClient``: the :class:`recap.llm.LLMClient` an agent holds when the gateway is a Ray actor.

Why a client object: agents only know ``complete(request)``. This one forwards the request to
the deployment's ``GatewayActor`` and blocks for the answer, re-raising failures as
``LLMError`` with the class the gateway gave them. It pickles (it holds only an actor handle),
so the pipeline can hand it to episode workers. A dead gateway actor becomes
``LLMError("server_error")``: transient from the agent's point of view.
"""

from __future__ import annotations

from typing import Any

import ray

from recap.llm import LLMError, LLMRequest, LLMResponse


def _unwrap(envelope: tuple) -> LLMResponse:
    if envelope[0] == "ok":
        return envelope[1]
    _, kind, message, retries, cost_usd, refusal = envelope
    raise LLMError(kind, message, retries=retries, cost_usd=cost_usd, refusal=refusal)


class GatewayClient:
    """The picklable :class:`recap.llm.LLMClient` of one deployment's ``GatewayActor`` (see the
    module docstring); ``timeout_s`` None: wait for the answer however long it takes."""

    def __init__(self, actor: Any, *, deployment: str | None = None, timeout_s: float | None = None):
        self.actor = actor
        self.deployment = deployment
        self.timeout_s = timeout_s

    def complete(self, request: LLMRequest) -> LLMResponse:
        try:
            envelope = ray.get(self.actor.complete.remote(request), timeout=self.timeout_s)
        except ray.exceptions.GetTimeoutError:
            raise LLMError("timeout", f"gateway {self.deployment} gave no answer within {self.timeout_s}s") from None
        except ray.exceptions.RayActorError as exc:
            raise LLMError("server_error", f"gateway {self.deployment} unavailable: {type(exc).__name__}") from None
        return _unwrap(envelope)

    async def acomplete(self, request: LLMRequest) -> LLMResponse:
        """The same, for callers that run in an event loop (async episode workers)."""
        try:
            envelope = await self.actor.complete.remote(request)
        except ray.exceptions.RayActorError as exc:
            raise LLMError("server_error", f"gateway {self.deployment} unavailable: {type(exc).__name__}") from None
        return _unwrap(envelope)

    def stats(self) -> dict[str, Any]:
        return ray.get(self.actor.stats.remote())

    def pause(self) -> None:
        ray.get(self.actor.pause.remote())

    def resume(self) -> None:
        ray.get(self.actor.resume.remote())

    def set_limits(self, *, rpm: int | None = None, tpm: int | None = None, max_concurrency: int | None = None) -> None:
        ray.get(self.actor.set_limits.remote(rpm, tpm, max_concurrency))
