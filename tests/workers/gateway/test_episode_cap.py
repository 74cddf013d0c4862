"""The per-instance cost cap (``limits.usd``) as a reservation: the gateway refuses a call whose
worst case would take its episode past the cap before anything is sent, and the episode ends
``episode_limit`` - the run and the model go on. Ledger, gateway core (litellm against the fake
server) and the agent's runtime, each asserted on exact values."""

from __future__ import annotations

import asyncio
import dataclasses
import json

import pyarrow.parquet as pq

from recap.baselines import ReActAgent, ReActConfig
from recap.blocksworld import BENCHMARK
from recap.llm import ChatMessage, LLMError, LLMRequest, LLMResponse
from schemas.outcomes import BudgetRefusal
from tests.doubles.offline_expert_client import OfflineExpert
from workers.gateway.ledger import BudgetLedger

USD = 10**12  # pico-dollars per dollar


def test_the_ledger_refuses_a_reservation_past_the_episodes_own_cap(tmp_path):
    led = BudgetLedger(tmp_path, fsync=False)
    # the episode spent 0.7 of its 1.0: a worst case of 0.3 fits exactly, 0.3 + 1 pico does not
    assert led.begin("ep#3", "m", 3 * USD // 10, episode=(USD, 7 * USD // 10))["status"] == "reserved"
    refused = led.begin("ep#4", "m", 3 * USD // 10 + 1, episode=(USD, 7 * USD // 10))
    assert refused == {
        "status": "refused",
        "message": "episode budget: spent $0.700000 + this call's worst case $0.300000 > the per-instance cap $1.000000",
        "refusal": {
            "scope": "episode",
            "model": "m",
            "cap_pico": USD,
            "committed_pico": 7 * USD // 10,
            "worst_pico": 3 * USD // 10 + 1,
        },
    }
    assert BudgetRefusal.from_dict(refused["refusal"]).scope == "episode"
    # a retry's reservation is checked the same way
    assert led.reserve("ep#4", "m", USD // 2, episode=(USD, USD // 2 + 1))["status"] == "refused"
    # nothing was reserved for the refusals; other episodes are not touched by this one's cap
    assert led.stats()["committed_usd"] == 0.3 and led.stats()["refusals"] == 2
    assert led.begin("other#0", "m", 5 * USD)["status"] == "reserved"
    led.close()


def test_a_recorded_result_is_served_whatever_the_episodes_cap_and_unpriced_calls_pass_it(tmp_path):
    led = BudgetLedger(tmp_path, fsync=False)
    r = led.begin("ep#0", "m", USD // 10)
    led.settle(r["rid"], USD // 20, "ok", {"text": "hi"})
    again = led.begin("ep#0", "m", USD // 10, episode=(USD // 100, USD // 100))  # no room left, but it costs nothing
    assert again == {"status": "recorded", "served_from": "ledger", "result": {"text": "hi"}}
    # an unpriced call (a self-hosted model with no price) cannot be counted against the cap
    assert led.begin("ep#1", "m", None, episode=(USD // 100, USD // 100))["status"] == "reserved"
    led.close()


def _request(i: int, cap: float | None, spent: float, text: str = "hello") -> LLMRequest:
    return LLMRequest(
        messages=(ChatMessage("user", text),),
        episode_id="u1-1",
        call_index=i,
        purpose="task",
        episode_cap_usd=cap,
        episode_spent_usd=spent,
    )


def test_the_gateway_sends_nothing_for_a_call_past_the_episodes_cap(tmp_path, fake_server):
    from workers.gateway.core import DeploymentGateway
    from workers.llm.providers import DeploymentConfig

    server = fake_server(reply="fine")
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "run.json").write_text(json.dumps({"run_id": "r1"}))
    cfg = DeploymentConfig(
        model="openai/fake-gpt", name="fake", api_base=server.base_url, params={"max_tokens": 16}, max_attempts=1
    )
    gw = DeploymentGateway(cfg, run_dir=run_dir, run_cap_usd=10.0)

    async def go() -> tuple[LLMResponse, LLMError, LLMResponse, LLMResponse]:
        first = await gw.complete(_request(0, 1.0, 0.0))
        try:
            await gw.complete(_request(1, 0.0001, 0.00009))
        except LLMError as exc:
            refused = exc
        worst = refused.refusal.worst_pico / USD
        # the same worst case fits exactly when the cap leaves that much
        fits = await gw.complete(_request(1, 0.00009 + worst, 0.00009))
        # a call already answered is served from the ledger, at no cost, even with no room left
        served = await gw.complete(_request(0, 0.0001, 0.0001))
        await gw.aclose()
        return first, refused, fits, served

    first, refused, fits, served = asyncio.run(go())
    assert (first.text, fits.text, served.served_from, served.cost_usd) == ("fine", "fine", "ledger", 0.0)
    r = refused.refusal
    assert (refused.kind, r.scope, r.model, r.cap_pico, r.committed_pico) == ("budget", "episode", "fake", 10**8, 9 * 10**7)
    assert r.worst_pico > 10**7  # more than the cap leaves: prompt bound + 16 output tokens at full price
    assert refused.message == (
        f"episode budget: spent $0.000090 + this call's worst case ${r.worst_pico / USD:.6f} > the per-instance cap $0.000100"
    )
    assert len(server.log) == 2  # the refused call never reached the provider
    rows = sorted(pq.read_table(run_dir / "llm_calls").to_pylist(), key=lambda row: (row["call_index"], row["status"]))
    assert [(row["call_index"], row["status"], row["error_kind"], row["served_from"]) for row in rows] == [
        (0, "ok", None, "provider"),
        (0, "ok", None, "ledger"),
        (1, "error", "budget", "provider"),
        (1, "ok", None, "provider"),
    ]
    assert not (run_dir / "events").exists()  # the cap at work is not a fault


class _CostingExpert(OfflineExpert):
    """The offline expert's replies at $0.4 each, refusing the third call as the gateway would for
    a $1.0 per-instance cap (the requests are kept: the test reads what each one carried)."""

    def complete(self, request: LLMRequest) -> LLMResponse:
        resp = super().complete(request)
        if len(self.requests) == 3:
            refusal = BudgetRefusal("episode", "offline/expert", USD, 8 * USD // 10, 3 * USD // 10)
            raise LLMError("budget", refusal.message, refusal=refusal)
        return dataclasses.replace(resp, cost_usd=0.4)


def test_an_episode_sends_its_cap_and_spend_and_ends_episode_limit_when_refused():
    env = BENCHMARK.make("blocksworld/4@1")
    client = _CostingExpert(env)
    agent = ReActAgent(ReActConfig(max_episode_cost_usd=1.0))
    result = agent.run(env, client, episode_id="ep", demonstration=False)
    assert [(q.episode_cap_usd, q.episode_spent_usd) for q in client.requests] == [(1.0, 0.0), (1.0, 0.4), (1.0, 0.8)]
    assert (result.end_reason, result.llm_calls, result.cost_usd) == ("episode_limit", 3, 0.8)
    assert result.error == "episode budget: spent $0.800000 + this call's worst case $0.300000 > the per-instance cap $1.000000"
    assert result.refusal is None  # not a run/model cap: nothing for the driver to stop
    # without a per-instance cap the requests carry none
    env2 = BENCHMARK.make("blocksworld/4@1")
    plain = OfflineExpert(env2)
    ReActAgent(ReActConfig()).run(env2, plain, episode_id="ep2", demonstration=False)
    assert {q.episode_cap_usd for q in plain.requests} == {None}
