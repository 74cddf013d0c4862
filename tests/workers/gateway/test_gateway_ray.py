"""The Ray wrappers: GatewayClient round trips, control calls beside requests, and actors killed
with ray.kill and recreated from the run folder."""

from __future__ import annotations

import pickle
import time
from pathlib import Path

import pytest
import ray  # noqa: E402

from recap.llm import LLMError  # noqa: E402
from schemas.parts import read_table  # noqa: E402
from tests.doubles.llm_requests import make_request  # noqa: E402
from workers.gateway.actors import RunGateways  # noqa: E402
from workers.llm.providers import DeploymentConfig  # noqa: E402

from .test_restart import _journal_spend  # noqa: E402

REPO = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def ray_session(ray_address):
    """The session's shared local Ray (tests/conftest.py); its workers import this checkout."""
    yield


def _config(server, **kw) -> DeploymentConfig:
    args = dict(
        model="openai/fake-gpt",
        api_base=server.base_url,
        max_concurrency=16,
        max_attempts=2,
        backoff_initial_s=0.01,
        params={"max_tokens": 20},
    )
    args.update(kw)
    return DeploymentConfig(**args)


def test_client_round_trip_error_kinds_and_control_beside_requests(ray_session, fake_server, run_dir):
    server = fake_server()
    gws = RunGateways([_config(server)], run_dir, "ray-run")
    client = pickle.loads(pickle.dumps(gws.client("openai/fake-gpt")))  # handed to episode workers
    resp = client.complete(make_request(0))
    assert resp.served_from == "provider" and resp.test_double and resp.completion_tokens == 12
    with pytest.raises(LLMError) as err:
        client.complete(make_request(1, "FAKE:ctx"))
    assert err.value.kind == "context_length" and err.value.retries == 0

    server.config.latency_s = 3.0
    arrived = server.arrivals
    pending = [client.actor.complete.remote(make_request(10 + i)) for i in range(6)]
    deadline = time.monotonic() + 30
    while server.arrivals < arrived + 6 and time.monotonic() < deadline:  # all six at the server (a loaded machine is slow)
        time.sleep(0.02)
    stats = client.stats()  # answered while the six requests are still waiting on the server
    ready, _ = ray.wait(pending, num_returns=len(pending), timeout=0)
    assert (server.arrivals - arrived, stats["inflight"], ready) == (6, 6, [])
    client.pause()
    held = client.actor.complete.remote(make_request(20))
    ray.get(pending)
    ready, _ = ray.wait([held], timeout=0.5)
    assert not ready  # paused: admitted nothing new
    client.set_limits(max_concurrency=4)
    client.resume()
    server.config.latency_s = 0.0
    assert ray.get(held)[0] == "ok"
    assert client.stats()["max_concurrency"] == 4
    gws.close()  # flushes the rows
    assert len(read_table(run_dir, "llm_calls")[0]) == 9


def test_killed_actors_are_recreated_and_continue_from_recorded_spend(ray_session, fake_server, run_dir):
    server = fake_server()
    cap = 0.002
    cfg = _config(server, max_concurrency=4)
    gws = RunGateways([cfg], run_dir, "ray-run", run_cap_usd=cap, budget="shared")
    client = gws.client(cfg.deployment_name)
    first = client.complete(make_request(0))
    for i in range(1, 6):
        client.complete(make_request(i))
    server.config.latency_s = 5.0
    arrived = server.arrivals
    in_flight = [client.actor.complete.remote(make_request(100 + i)) for i in range(4)]
    deadline = time.monotonic() + 30
    while server.arrivals < arrived + 4 and time.monotonic() < deadline:  # reserved and sent, waiting on the server
        time.sleep(0.02)
    ray.kill(gws.actors[cfg.deployment_name], no_restart=True)
    ray.kill(gws.budget, no_restart=True)
    with pytest.raises(ray.exceptions.RayActorError):
        ray.get(in_flight[0])
    settled_before, open_before = _journal_spend(run_dir)
    assert open_before > 0

    server.config.latency_s = 0.0
    again = RunGateways([cfg], run_dir, "ray-run", run_cap_usd=cap, budget="shared")
    client2 = again.client(cfg.deployment_name)
    restored = ray.get(again.budget.stats.remote())
    assert restored["spent_pico"] == settled_before + open_before and restored["restored_orphans"] == 4
    served = client2.complete(make_request(0, "answered from the ledger"))
    assert (served.served_from, served.text, served.cost_usd) == ("ledger", first.text, 0.0)
    refused = 0
    for i in range(200, 300):
        try:
            client2.complete(make_request(i))
        except LLMError as exc:
            assert exc.kind == "budget"
            refused += 1
            break
    assert refused == 1
    final = ray.get(again.budget.stats.remote())
    assert final["spent_usd"] <= cap
    again.close()
