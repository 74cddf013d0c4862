"""A gateway killed with SIGKILL mid-run and recreated from the run folder continues from the
recorded spend: exact restore of the journal, open reservations charged at worst case,
recorded results served again, and the cap still holds."""

from __future__ import annotations

import asyncio
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from recap.llm import LLMError
from tests.doubles.llm_requests import make_request
from workers.gateway.core import DeploymentGateway
from workers.gateway.ledger import JOURNAL_NAME
from workers.llm.providers import DeploymentConfig

REPO = Path(__file__).resolve().parents[3]


def _journal_spend(run_dir: Path) -> tuple[int, int]:
    """(settled pico, open reservation pico) read straight from the journal file."""
    settled = 0
    open_: dict[int, int] = {}
    for line in (run_dir / JOURNAL_NAME).read_text().splitlines():
        e = json.loads(line)
        if e["op"] == "reserve":
            open_[e["rid"]] = e["pico"]
        else:
            open_.pop(e["rid"])
            settled += e["pico"]
    return settled, sum(open_.values())


def test_sigkilled_gateway_continues_from_recorded_spend(fake_server, run_dir):
    server = fake_server(latency_s=0.5)
    cap = 0.003
    child = subprocess.Popen(
        [sys.executable, "-m", "tests.workers.gateway.crash_child", str(run_dir), server.base_url, str(cap)],
        cwd=REPO,
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    paid: dict[str, tuple[int, str]] = {}
    try:
        for line in child.stdout:  # type: ignore[union-attr]
            if line.startswith("OK "):
                _, key, pico, text = line.rstrip("\n").split(" ", 3)
                paid[key] = (int(pico), text)
                if len(paid) >= 8:
                    break
        time.sleep(0.2)  # the next calls are admitted, reserved and waiting on the server
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait(30)
    assert len(paid) >= 8
    settled_before, open_before = _journal_spend(run_dir)
    assert open_before > 0  # calls were in flight when the process died

    server.config.latency_s = 0.0
    gw = DeploymentGateway(
        DeploymentConfig(model="openai/fake-gpt", api_base=server.base_url, max_concurrency=20, params={"max_tokens": 20}),
        run_dir=run_dir,
        run_id="kill-test",
        run_cap_usd=cap,
    )

    async def go():
        restored = await gw.budget.stats()
        arrivals = len(server.log)
        key, (_pico, text) = next(iter(paid.items()))
        again = await gw.complete(make_request(int(key.split("#")[1]), "ignored: answered from the ledger"))
        assert len(server.log) == arrivals and (again.served_from, again.text, again.cost_usd) == ("ledger", text, 0.0)
        results = await asyncio.gather(*[gw.complete(make_request(100 + i)) for i in range(120)], return_exceptions=True)
        final = await gw.budget.stats()
        await gw.aclose()
        return restored, results, final

    restored, results, final = asyncio.run(go())
    # exact restore: everything settled before the kill, plus the open reservations at worst case
    assert restored["spent_pico"] == settled_before + open_before
    assert restored["restored_orphans"] >= 1 and restored["reserved_usd"] == 0
    assert restored["spent_pico"] >= sum(p for p, _ in paid.values())
    refused = [r for r in results if isinstance(r, LLMError)]
    assert refused and {e.kind for e in refused} == {"budget"}
    assert final["spent_usd"] <= cap
