"""A sweep through the real gateway and budget actors (``pipeline.gateway_backend``): the gateway
spends a dollar lease from the run's QuotaActor and reports its settled calls in batches, so the
budget authority serves no request per model call - and the spend is still exact, in the ledger,
in ``llm_calls`` and in the run summary, with no reservation left open."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from pipeline.driver import Driver, prepare
from pipeline.gateway_backend import GatewayBackend
from pipeline.spec import parse_spec
from pipeline.sqlview import open_tables
from pipeline.store import RunStore
from workers.gateway.ledger import BudgetLedger

SWEEP = """run: leased
output: {out}
models:
  - model: openai/fake-gpt
    api_base: {url}
    api_key_env: RECAP_FAKE_KEY
methods: [{{method: react}}]
environments: [{{benchmark: blocksworld, tasks: ["3"]}}]
limits: {{llm_calls: 6}}
workers: 3
"""


class _Recording(GatewayBackend):
    """The product's backend; the authority's figures are kept once the gateways have closed."""

    final: dict[str, Any] = {}

    def flush(self) -> None:
        import ray

        closing = not self._closed and self.budget is not None
        super().flush()
        if closing:
            _Recording.final = ray.get(self.budget.stats.remote())


@pytest.fixture(scope="module")
def fast_server():
    from workers.llm.offline.fake_server import FakeServer, FakeServerConfig

    server = FakeServer(FakeServerConfig(latency_s=0.02))
    url = server.start_in_thread()
    yield url
    server.stop_thread()


def test_the_budget_authority_serves_no_request_per_model_call_and_spend_stays_exact(
    ray_address, fast_server, tmp_path: Path, monkeypatch
):
    monkeypatch.setenv("RECAP_FAKE_KEY", "not-a-secret")
    out = tmp_path / "leased"
    text = SWEEP.format(out=out, url=fast_server)
    spec = parse_spec(text, "sweep.yaml")
    summary = Driver(prepare(spec, text), _Recording(spec), progress="off").run()
    assert summary.exit_code() == 0
    con, _ = open_tables(RunStore(out))
    ((n, cost),) = con.execute("select count(*), sum(cost_usd) from llm_calls where status = 'ok'").fetchall()
    assert n >= 3 and con.execute("select count(*) from llm_calls where status <> 'ok'").fetchall() == [(0,)]

    stats = _Recording.final
    requests = stats["requests"]
    # before: a begin (awaited) and a settle per model call; now the calls come in reports
    assert (requests["begin"], requests["reserve"], requests["settle"], requests["charge_worst"]) == (0, 0, 0, 0)
    assert stats["settled_in_leases"] == n and 1 <= requests["report"] <= n
    # the spend is exact: the ledger, the llm_calls rows and the run summary agree to the pico-dollar
    assert abs(stats["spent_usd"] - cost) < 1e-12 and abs(summary.spend_usd - cost) < 1e-12
    assert (stats["open_reservations"], stats["open_leases"], stats["reserved_usd"]) == (0, 0, 0)
    # the journal replays to the same spend, every call's result recorded (a re-sent call is served from it)
    ledger = BudgetLedger(out, fsync=False)
    try:
        assert ledger.stats()["spent_pico"] == stats["spent_pico"] and ledger.stats()["recorded_results"] == n
        keys = [r[0] for r in con.execute("select call_key from llm_calls").fetchall()]
        assert len(keys) == n and all(ledger.begin(k, "openai/fake-gpt", 10**9)["status"] == "recorded" for k in keys)
    finally:
        ledger.close()
