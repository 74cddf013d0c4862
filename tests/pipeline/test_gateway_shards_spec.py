"""``models[].gateway_shards``: its range is checked in one line, and the episode workers take a
sharded model's gateway actors round robin (the worker pool hands each its factory)."""

from __future__ import annotations

import pickle

import pytest

from pipeline.errors import SpecError
from pipeline.gateway_backend import GatewayBackend, GatewayFactory
from pipeline.spec import parse_spec
from pipeline.worker_pool import RayWorkerPool

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
