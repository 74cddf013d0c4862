"""``BlockingGateway``: the gateway core as a synchronous ``LLMClient``, without Ray.

Why: agents call ``client.complete(request)`` synchronously. A single-process run (a debug
session, the real-model check, a notebook) still wants the gateway's records, budget and
rate limits, so the core runs on a private event-loop thread and ``complete`` blocks on it.
Many threads may call ``complete`` at once; they share the one gateway.
"""

from __future__ import annotations

import asyncio
import threading
from typing import Any

from recap.llm import LLMRequest, LLMResponse
from workers.gateway.core import DeploymentGateway
from workers.llm.providers import DeploymentConfig


class BlockingGateway:
    """A synchronous :class:`recap.llm.LLMClient` over one deployment's gateway core, which runs on
    a private event-loop thread (see the module docstring); use it as a context manager so the
    gateway is closed."""

    def __init__(self, config: DeploymentConfig, **gateway_kwargs: Any):
        self.core = DeploymentGateway(config, **gateway_kwargs)
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="gateway-loop", daemon=True)
        self._thread.start()

    def _run(self, coro: Any) -> Any:
        return asyncio.run_coroutine_threadsafe(coro, self._loop).result()

    def complete(self, request: LLMRequest) -> LLMResponse:
        return self._run(self.core.complete(request))

    def stats(self) -> dict[str, Any]:
        async def read() -> dict[str, Any]:
            return self.core.stats()

        return self._run(read())

    def budget_stats(self) -> dict[str, Any]:
        return self._run(self.core.budget.stats())

    def close(self) -> None:
        """Flush the rows, close the ledger and stop the loop thread."""
        if not self._thread.is_alive():
            return

        async def shutdown() -> None:
            await self.core.aclose()
            # litellm leaves a logging worker task in the loop: end it like asyncio.run would
            others = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
            for t in others:
                t.cancel()
            await asyncio.gather(*others, return_exceptions=True)

        try:
            self._run(shutdown())
        finally:
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(10)
            self._loop.close()

    def __enter__(self) -> BlockingGateway:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
