"""Gateway shards on Ray: four GatewayActors of one deployment share its RPM quota and the run cap
through the QuotaActor's leases, spread over workers round robin, and a killed shard's lease is
charged by its next incarnation (the cap holds)."""

from __future__ import annotations

import pytest
import ray

from schemas.parts import read_table
from tests.doubles.llm_requests import make_request
from workers.gateway.actors import GatewayActor, RunGateways
from workers.llm.offline.fake_server import window_maxima
from workers.llm.pricing import default_prices, usd_to_pico
from workers.llm.providers import DeploymentConfig

MODEL = "openai/fake-gpt"
PRICE = default_prices().get(MODEL)


@pytest.fixture(scope="module")
def ray_session(ray_address):
    yield


@pytest.mark.slow  # six gateway actors start (each imports litellm): ~30 s on 2 quiet cores
def test_four_ray_shards_share_the_quota_and_the_cap_and_a_killed_shards_lease_is_charged(ray_session, fake_server, run_dir):
    q, window = 20, 1.0
    server = fake_server(rpm=q, window_s=window, latency_s=0.05)  # answers 429 past the quota
    cfg = DeploymentConfig(
        model=MODEL,
        api_base=server.base_url,
        rpm=q,
        window_s=window,
        window_pad_s=0.05,
        max_concurrency=16,
        max_attempts=2,
        backoff_initial_s=0.01,
        attempt_timeout_s=5.0,
        params={"max_tokens": 20},
    )
    name = cfg.deployment_name
    cap = 0.0015  # about 40 of the 63 calls
    gws = RunGateways([cfg], run_dir, "ray-run", run_cap_usd=cap, shards=4)
    shards = gws.shards[name]
    clients = [gws.client(name, worker=w) for w in range(8)]
    assert [c.actor for c in clients] == shards + shards  # workers take the shards round robin

    refs = [clients[i % 8].actor.complete.remote(make_request(i, f"question {i}")) for i in range(60)]
    ray.wait(refs, num_returns=12, timeout=120)
    ray.kill(shards[2], no_restart=True)  # mid-run: its lease and reservations stay open
    outcomes = []
    for ref in refs:
        try:
            outcomes.append(ray.get(ref, timeout=120)[:2])
        except ray.exceptions.RayActorError:
            outcomes.append(("died", None))
    # the shard's next incarnation charges what its predecessor held, then serves calls
    reborn = GatewayActor.remote(cfg, str(run_dir), "ray-run", gws.budget, shard=(2, 4))
    shards[2] = reborn
    later = [ray.get(reborn.complete.remote(make_request(1000 + i, f"later {i}")))[:2] for i in range(3)]
    reborn_stats = ray.get(reborn.stats.remote())
    gws.close()
    stats = ray.get(gws.budget.stats.remote())

    kinds = {o[0] if o[0] != "error" else o[1] for o in outcomes + later}
    assert kinds <= {"ok", "budget", "died"} and "ok" in kinds and "budget" in kinds and "died" in kinds
    assert reborn_stats["calls"]["orphans_adopted"] >= 1
    # the cap: what the provider really billed <= what the ledger charged <= the cap, nothing left open
    true_bill = sum(PRICE.cost_pico(c.prompt_tokens, c.cached_tokens, c.completion_tokens) for c in server.log if c.status == 200)
    assert true_bill <= stats["spent_pico"] <= usd_to_pico(cap)
    assert stats["open_reservations"] == 0 and stats["reserved_usd"] == 0
    # the quota: not one 429, no window past q
    assert {c.status for c in server.log} == {200}
    assert window_maxima(server.log, window)[0] <= q
    rows = read_table(run_dir, "llm_calls")[0].to_pylist()
    # (a killed shard loses the rows it had not flushed yet, never more)
    assert 0 < sum(1 for r in rows if r["status"] == "ok") <= sum(1 for o in outcomes + later if o[0] == "ok")
