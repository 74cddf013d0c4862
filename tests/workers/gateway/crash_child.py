"""Child process of the kill test: a gateway making calls until it is killed with SIGKILL.

Run as ``python -m tests.workers.gateway.crash_child RUN_DIR BASE_URL CAP_USD``; prints one line per
finished call (``OK <call_key> <cost pico> <text>``) so the parent knows what was paid.
"""

from __future__ import annotations

import asyncio
import sys

from recap.llm import ChatMessage, LLMRequest
from workers.gateway.core import DeploymentGateway
from workers.llm.providers import DeploymentConfig


async def main(run_dir: str, base_url: str, cap_usd: float) -> None:
    gw = DeploymentGateway(
        DeploymentConfig(model="openai/fake-gpt", api_base=base_url, max_concurrency=4, params={"max_tokens": 20}),
        run_dir=run_dir,
        run_id="kill-test",
        run_cap_usd=cap_usd,
    )
    print("READY", flush=True)

    async def one(i: int) -> None:
        req = LLMRequest(messages=(ChatMessage("user", f"request number {i}"),), episode_id="ep", call_index=i, purpose="task")
        resp = await gw.complete(req)
        print(f"OK {req.call_key} {round(resp.cost_usd * 10**12)} {resp.text}", flush=True)

    await asyncio.gather(*[one(i) for i in range(40)])
    print("DONE", flush=True)
    await asyncio.sleep(3600)  # wait to be killed


if __name__ == "__main__":
    asyncio.run(main(sys.argv[1], sys.argv[2], float(sys.argv[3])))
