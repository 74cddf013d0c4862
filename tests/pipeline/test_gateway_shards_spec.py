"""``models[].gateway_shards``: its range is checked in one line, and the episode workers take a
sharded model's gateway actors round robin (the worker pool hands each its factory)."""

from __future__ import annotations

import pickle

import pytest

from pipeline.errors import SpecError
from pipeline.gateway_backend import GatewayBackend, GatewayFactory
from pipeline.spec import parse_spec
from pipeline.worker_pool import RayWorkerPool
from tests.pipeline.test_model_config import E2E as TWO_NAMES

SPEC = """
run: shards
output: /tmp/never-written-shards
models:
  - model: offline/expert
    gateway_shards: {n}
methods: [{{method: recap}}]
environments: [{{benchmark: blocksworld, tasks: ["3"]}}]
"""


@pytest.mark.parametrize("bad,why", [("0", "0 is out of range [1, 64]"), ("65", "65 is out of range [1, 64]"), ("true", "")])
def test_a_bad_shard_count_is_refused_in_one_line(bad, why):
    with pytest.raises(SpecError) as err:
        parse_spec(SPEC.format(n=bad), "sweep.yaml")
    message = str(err.value)
    assert "\n" not in message and "models[0].gateway_shards" in message and why in message


def test_the_backend_plans_the_shards_and_workers_take_them_round_robin():
    spec = parse_spec(SPEC.format(n=3), "sweep.yaml")
    assert GatewayBackend(spec).shards == {"offline/expert": 3}
    factory = GatewayFactory({"offline/expert": ["shard0", "shard1", "shard2"], "other": "single"})

    class Worker:
        made: list = []

        @classmethod
        def remote(cls, wid, run_id, sink, factory):
            cls.made.append(pickle.loads(pickle.dumps(factory)))  # as Ray hands it to the actor
            return wid

    pool = RayWorkerPool(Worker, "run", sink=None, factory=factory, session="s")
    for _ in range(7):
        pool._new_slot()
    assert [f.client("offline/expert") for f in Worker.made] == ["shard0", "shard1", "shard2"] * 2 + ["shard0"]
    assert {f.client("other") for f in Worker.made} == {"single"}


#: test_model_config's sweep of two names on one model string, each name's gateway in two shards
E2E = (
    TWO_NAMES.replace("run: {name}", "run: shards-e2e")
    .replace("    cap_usd: {cap}\n", "    cap_usd: {cap}\n    gateway_shards: 2\n")
    .replace("    cap_usd: 1.0\n", "    cap_usd: 1.0\n    gateway_shards: 2\n")
)


@pytest.mark.slow  # a sweep on Ray with four gateway actors and the quota actor
def test_a_sweep_with_gateway_shards_keeps_each_models_cap_and_spend(ray_address, tmp_path):
    import json

    from pipeline.driver import Driver, prepare
    from pipeline.gateway_backend import make_backend
    from pipeline.sqlview import open_tables
    from pipeline.store import RunStore
    from workers.gateway.ledger import JOURNAL_NAME
    from workers.gateway.quota import LEASE_KEY

    out = tmp_path / "e2e"
    cap = 0.012  # about two thirds of what the three episodes of expert-a need
    text = E2E.format(out=out, cap=cap)
    spec = parse_spec(text, "sweep.yaml")
    summary = Driver(prepare(spec, text), make_backend(spec), progress="off").run()
    assert (summary.total, summary.stopped) == (6, "expert-a capped")
    con, bad = open_tables(RunStore(out))
    assert bad == []
    q = lambda sql: con.execute(sql).fetchall()  # noqa: E731
    assert q("select end_reason, count(*) from episodes where model = 'expert-b' group by 1") == [("success", 3)]
    spent = dict(q("select model_name, sum(cost_usd) from llm_calls group by 1"))
    assert 0 < spent["expert-a"] <= cap and spent["expert-b"] > cap
    # expert-b's calls went through leases (expert-a's cap is too tight for one: call by call), and
    # the journal's spend by name is the rows' spend, exactly
    journal = [json.loads(x) for x in (out / JOURNAL_NAME).read_text().splitlines()]
    assert {e["name"] for e in journal if e["key"].startswith(LEASE_KEY)} == {"expert-b"}
    by_name = {n: sum(e["pico"] for e in journal if e["op"] == "settle" and e["name"] == n) / 10**12 for n in spent}
    assert by_name == pytest.approx(spent, abs=1e-9)
