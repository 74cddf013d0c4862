"""The Ray path with group-committed reservations in the shared BudgetActor: every call of two
concurrent gateways is reserved and settled, and a settlement the gateway does not wait for
still reaches the budget before the gateway's next request - a repeated call_key is served from
the ledger, never paid twice.
How many fdatasyncs a batch shares depends on Ray's timing here; the exact sharing is asserted
in test_journal_group_commit.py. Timings are bench/gateway.py's job, not a test's."""

from __future__ import annotations

import ray  # noqa: E402

from tests.doubles.llm_requests import make_request  # noqa: E402
from workers.gateway.actors import RunGateways  # noqa: E402
from workers.llm.providers import DeploymentConfig  # noqa: E402

from .test_gateway_ray import ray_session  # noqa: E402,F401


def _config(server, name: str) -> DeploymentConfig:
    return DeploymentConfig(
        model="openai/fake-gpt", api_base=server.base_url, name=name, max_concurrency=16, params={"max_tokens": 20}
    )


def test_shared_budget_group_commits_and_deferred_settlements_keep_idempotency(ray_session, fake_server, run_dir):  # noqa: F811
    server = fake_server(latency_s=0.2)
    gws = RunGateways([_config(server, "one"), _config(server, "two")], run_dir, "ray-run", budget="shared")
    one, two = gws.client("one"), gws.client("two")
    refs = [
        c.actor.complete.remote(make_request(i, episode=f"ep-{name}"))
        for name, c in (("one", one), ("two", two))
        for i in range(12)
    ]
    envelopes = ray.get(refs)
    assert [e[0] for e in envelopes] == ["ok"] * 24
    arrivals = len(server.log)
    server.config.latency_s = 0.0
    for i in range(5):  # each answer, then at once the same call again: the settlement is there
        first = one.complete(make_request(100 + i, episode="ep-again"))
        again = one.complete(make_request(100 + i, "not sent: served from the ledger", episode="ep-again"))
        assert (again.served_from, again.text, again.cost_usd) == ("ledger", first.text, 0.0)
    assert len(server.log) == arrivals + 5
    gws.close()
    stats = ray.get(gws.budget.stats.remote())
    assert (stats["settled"], stats["open_reservations"], stats["recorded_results"]) == (29, 0, 29)
    assert stats["spent_pico"] > 0 and stats["journal_syncs"] >= 5  # at least one per sequential call
