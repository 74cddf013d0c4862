"""A sweep that serves its model itself: the test-double engine deployed through Ray Serve with 2
replicas, a sweep run on it by 3 workers (so the replicas, each running one answer at a time, queue
calls that the gateway's queue feed reads), one replica killed mid-run (its calls retried as infrastructure, every
unit done once, nothing paid twice), everything taken down at the end, and the replica-hours
charged to the ledger and attributed to the calls (pipeline/serving)."""

from __future__ import annotations

import json

import pytest

from pipeline.spec import parse_spec
from pipeline.store import RunStore
from workers.gateway.ledger import JOURNAL_NAME

PICO = 10**12
#: USD per replica-hour: 36 is a cent per replica-second, so a short run costs a measurable amount
REPLICA_HOUR = 36.0

SPEC = """run: {name}
output: {out}
models:
  - model: offline/expert
    label: served-expert
    serve: {{replicas: 2, max_in_flight: 4, engine_args: {{latency_s: 0.4, max_running: 1}}}}
    prices: {{replica_hour: {price}}}
methods: [{{method: react}}]
environments: [{{benchmark: blocksworld, instances: [blocksworld/5@1, blocksworld/5@2, blocksworld/5@3, blocksworld/3@1]}}]
workers: 3
order: plan
"""


def _serve_actors() -> list[str]:
    import ray

    return sorted(a["name"] for a in ray.util.list_named_actors(all_namespaces=True) if a["namespace"] == "serve")


def _kill_a_busy_replica(app: str, timeout_s: float = 30.0) -> str:
    """Kill a replica of ``app`` while it holds a call (never restarted by Ray: Serve must start
    another); its name."""
    import time

    import ray

    names = [n for n in _serve_actors() if "REPLICA" in n and app in n]
    assert len(names) == 2, names
    handles = {n: ray.get_actor(n, namespace="serve") for n in names}
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        for name, handle in handles.items():
            if ray.get(handle.get_num_ongoing_requests.remote()) > 0:
                ray.kill(handle, no_restart=True)
                return name
        time.sleep(0.02)
    raise AssertionError("no replica held a call")


def test_a_served_test_double_runs_a_sweep_survives_a_lost_replica_and_is_taken_down(ray_address, tmp_path):
    from ray import serve

    from pipeline.attempts import Hooks
    from pipeline.driver import Driver, prepare
    from pipeline.gateway_backend import make_backend
    from pipeline.serving.cost import attribution_sql
    from pipeline.serving.service import app_prefix, serve_apps, serve_running
    from pipeline.sqlview import open_tables

    assert not serve_running()  # this test's cluster has no Serve of its own before the sweep
    out = tmp_path / "served"
    text = SPEC.format(name="served", out=out, price=REPLICA_HOUR)
    spec = parse_spec(text, "sweep.yaml")
    killed: list[str] = []
    seen: dict[str, object] = {}

    def on_result(unit, attempt, outcome):  # the first episode back: the last unit is mid-episode
        if killed:
            return
        apps = [a for a in serve_apps() if a.startswith("recap-")]
        seen["apps"] = apps
        killed.append(_kill_a_busy_replica(apps[0]))

    summary = Driver(prepare(spec, text), make_backend(spec), progress="off", hooks=Hooks(on_result=on_result)).run()
    assert summary.all_done and (summary.total, summary.finished_now) == (4, 4)
    run_id = json.loads((out / "run.json").read_text())["run_id"]
    assert seen["apps"] == [app_prefix(run_id) + "0"] and len(killed) == 1

    con, bad = open_tables(RunStore(out))
    assert bad == []
    q = lambda sql: con.execute(sql).fetchall()  # noqa: E731
    # every unit done once (a lost replica is not the episode's failure), every episode a success
    assert q("select attempt, end_reason, count(*) from episodes group by 1, 2") == [(1, "success", 4)]
    # the calls went over HTTP to the served test double, labelled one, at the replicas' concurrency
    assert q("select distinct model, model_name, test_double, status from llm_calls") == [
        ("offline/expert", "served-expert", True, "ok")
    ]
    started = [json.loads(d) for (d,) in q("select detail from events where kind = 'serve_started'")]
    assert [(s["model"], s["engine"], s["replicas"], s["max_in_flight"], s["test_double"]) for s in started] == [
        ("served-expert", "test-double", 2, 4, True)
    ]
    assert started[0]["api_base"].endswith(f"/recap/{run_id}/0/v1")
    # the calls cut by the lost replica were retried by the gateway as a server error
    retried = q("select count(*) from events where kind = 'retry' and detail->>'kind' = 'server_error'")
    calls_retried = q("select coalesce(sum(retries), 0) from llm_calls")
    assert retried[0][0] >= 1 and calls_retried[0][0] >= 1
    # the in-flight limit adapted between one call a replica and replicas x max_in_flight: the lost
    # replica's 5xx, the survivors' slower replies or their queue lowered it, each change an events row
    limits = q(
        "select detail->>'reason', (detail->>'before')::int, (detail->>'limit')::int, (detail->>'queue')::int "
        "from events where kind = 'concurrency_limit' and detail->>'deployment' = 'served-expert' order by ts"
    )
    assert limits and limits[0][0] in ("error", "latency", "queue") and limits[0][1:3] == (8, 4)
    assert all(2 <= after <= 8 and (after < before) == (why != "recovered") for why, before, after, _ in limits)
    # each replica runs one answer at a time (max_running: 1): two calls on one replica - the
    # survivor's while the lost one is replaced - queue one, which the gateway read from the
    # replicas' vLLM gauge (workers.gateway.queue_feed) and halved the limit for
    queued = [(before, after, queue) for why, before, after, queue in limits if why == "queue"]
    assert queued and all(queue >= 1 and after < before for before, after, queue in queued)

    # taken down: no application of the run, Serve (which the sweep started) shut down, no actor of it left
    assert not serve_running() and serve_apps() == {} and _serve_actors() == []
    assert q("select detail->>'model' from events where kind = 'serve_stopped'") == [("served-expert",)]

    # cost: the replica-hours held, charged to the ledger as they accrued; the run's spend is them
    (cost,) = [json.loads(d) for (d,) in q("select detail from events where kind = 'serve_cost' and severity = 'info'")]
    assert cost["replicas"] == 2 and cost["gpus_per_replica"] == 0 and cost["gpu_hours"] == 0
    assert cost["replica_hours"] == pytest.approx(2 * cost["held_s"] / 3600, rel=1e-6)
    assert cost["usd"] == pytest.approx(cost["replica_hours"] * REPLICA_HOUR, rel=1e-3)
    assert cost["held_s"] >= started[0]["ready_s"] > 0
    journal = [json.loads(x) for x in (out / JOURNAL_NAME).read_text().splitlines()]
    serve_keys = {e["rid"]: e["key"] for e in journal if e["op"] == "reserve" and e["key"].startswith(f"serve:{run_id}:")}
    charged = [e for e in journal if e["op"] == "settle" and e["rid"] in serve_keys]
    assert len(charged) == len(serve_keys) >= 1 and all(e["name"] == "served-expert" for e in charged)
    assert sum(e["pico"] for e in charged) / PICO == pytest.approx(cost["usd"], abs=1e-9)
    assert summary.spend_usd == pytest.approx(
        cost["usd"], abs=1e-6
    )  # (the ledger reports micro-dollars) the tokens of a served model cost nothing more
    assert q("select sum(cost_usd) from llm_calls") == [(0.0,)]
    # attributed to the calls by their tokens: the shares add up to the serving cost
    shares = q(attribution_sql("served-expert"))
    assert len(shares) == q("select count(*) from llm_calls")[0][0]
    assert sum(s[3] for s in shares) == pytest.approx(cost["usd"], rel=1e-9)
    tokens = {s[0]: s[2] for s in shares}
    big, small = max(tokens, key=tokens.__getitem__), min(tokens, key=tokens.__getitem__)
    share = {s[0]: s[3] for s in shares}
    assert share[big] / share[small] == pytest.approx(tokens[big] / tokens[small])
    serve.shutdown()  # nothing to do (already down); leaves the shared cluster clean whatever happened
