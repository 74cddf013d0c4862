"""The queue feed of a served model (workers/gateway/queue_feed.py, workers/serving/queue_source.py):
the Prometheus gauges parsed from the engines' exact exposition, the test double's replicas
read and summed, and the adaptive limit's exact sequence when they report a queue. Ray-free: the
replica actors are stood in for by objects with the same ``.remote()`` methods."""

from __future__ import annotations

import asyncio
from types import SimpleNamespace
from typing import Any

import pytest

from tests.workers.gateway.adaptive_admission import adaptive_controller
from workers.gateway.adaptive import LimitChange
from workers.gateway.queue_feed import SGLANG_WAITING, VLLM_WAITING, QueueFeed, waiting_requests
from workers.llm.providers import QueueSource
from workers.serving import queue_source
from workers.serving.test_double import TestDoubleServer, metrics_text

#: vLLM's own /metrics (prometheus_client's exposition): one AsyncLLM with two engine cores
#: (data parallel), beside a histogram and a counter whose names share the prefix
VLLM_TEXT = """# HELP vllm:num_requests_running Number of requests in model execution batches.
# TYPE vllm:num_requests_running gauge
vllm:num_requests_running{engine="0",model_name="Qwen/Qwen2.5-7B-Instruct"} 16.0
vllm:num_requests_running{engine="1",model_name="Qwen/Qwen2.5-7B-Instruct"} 15.0
# HELP vllm:num_requests_waiting Number of requests waiting to be processed.
# TYPE vllm:num_requests_waiting gauge
vllm:num_requests_waiting{engine="0",model_name="Qwen/Qwen2.5-7B-Instruct"} 3.0
vllm:num_requests_waiting{engine="1",model_name="Qwen/Qwen2.5-7B-Instruct"} 4.0
# HELP vllm:num_requests_waiting_created Number of requests waiting to be processed.
# HELP vllm:time_to_first_token_seconds Histogram of time to first token in seconds.
# TYPE vllm:time_to_first_token_seconds histogram
vllm:time_to_first_token_seconds_bucket{engine="0",le="0.001",model_name="Qwen/Qwen2.5-7B-Instruct"} 0.0
vllm:time_to_first_token_seconds_count{engine="0",model_name="Qwen/Qwen2.5-7B-Instruct"} 1234.0
"""

#: the same gauge as Ray's metrics agent exports it (ray.serve.llm's RayPrometheusStatLogger), two
#: replicas of this model on one node, one of another application's model, and a NaN
RAY_TEXT = """# HELP ray_vllm_num_requests_waiting Number of requests waiting to be processed.
# TYPE ray_vllm_num_requests_waiting gauge
ray_vllm_num_requests_waiting{Component="core_worker",NodeAddress="10.0.0.5",ReplicaId="a1b2",SessionName="session_2026",Version="2.60.0",WorkerId="7f",engine="0",model_name="Qwen/Qwen2.5-7B-Instruct"} 2.0
ray_vllm_num_requests_waiting{Component="core_worker",NodeAddress="10.0.0.5",ReplicaId="c3d4",SessionName="session_2026",Version="2.60.0",WorkerId="8e",engine="0",model_name="Qwen/Qwen2.5-7B-Instruct"} 5.0 1764370000000
ray_vllm_num_requests_waiting{Component="core_worker",NodeAddress="10.0.0.5",ReplicaId="e5f6",SessionName="session_2026",Version="2.60.0",WorkerId="9d",engine="0",model_name="meta-llama/Llama-3.1-8B-Instruct"} 9.0
ray_vllm_num_requests_waiting{Component="core_worker",NodeAddress="10.0.0.6",ReplicaId="g7h8",SessionName="session_2026",Version="2.60.0",WorkerId="9e",engine="0",model_name="Qwen/Qwen2.5-7B-Instruct"} NaN
"""

QWEN = {"model_name": "Qwen/Qwen2.5-7B-Instruct"}


def test_vllms_waiting_gauge_is_summed_over_its_engines_and_nothing_else_is_counted():
    assert waiting_requests(VLLM_TEXT, VLLM_WAITING) == 7
    assert waiting_requests(VLLM_TEXT, VLLM_WAITING, QWEN) == 7
    assert waiting_requests(VLLM_TEXT, VLLM_WAITING, {"model_name": "other"}) is None
    assert waiting_requests(VLLM_TEXT, ["vllm:num_requests_running"]) == 31


def test_the_gauge_as_ray_exports_it_is_summed_over_the_replicas_of_the_served_model_only():
    # 2 + 5 on this model's replicas (a timestamp after the value is read past); the other
    # application's replica is filtered out by its model_name; a NaN sample adds nothing
    assert waiting_requests(RAY_TEXT, VLLM_WAITING, QWEN) == 7
    assert waiting_requests(RAY_TEXT, VLLM_WAITING) == 16
    # two nodes' texts: each counted
    assert waiting_requests(RAY_TEXT + RAY_TEXT, VLLM_WAITING, QWEN) == 14


def test_sglangs_queue_gauge_and_label_values_with_quotes_braces_and_commas():
    text = (
        "# TYPE sglang:num_queue_reqs gauge\n"
        'sglang:num_queue_reqs{model_name="Qwen/Qwen2.5-7B-Instruct",note="a \\"b\\", {c}"} 6\n'
        'sglang:num_queue_reqs{model_name="Qwen/Qwen2.5-7B-Instruct",} 1e0\n'
        "sglang:num_running_reqs 12\n"
        "not a sample line\n"
    )
    assert waiting_requests(text, SGLANG_WAITING, QWEN) == 7
    assert waiting_requests(text, SGLANG_WAITING, {"note": 'a "b", {c}'}) == 6
    # a server that does not report the gauge: no figure (not a queue of 0)
    assert waiting_requests("# nothing here\n", SGLANG_WAITING) is None
    assert waiting_requests("vllm:num_requests_waiting 0\n", VLLM_WAITING) == 0


def test_the_test_double_exposes_vllms_gauges_in_vllms_format():
    text = metrics_text("offline/expert", waiting=2, running=1)
    assert text.splitlines()[3:] == [
        "# HELP vllm:num_requests_waiting Number of requests waiting to be processed.",
        "# TYPE vllm:num_requests_waiting gauge",
        'vllm:num_requests_waiting{engine="0",model_name="offline/expert"} 2.0',
    ]
    assert waiting_requests(text, VLLM_WAITING, {"model_name": "offline/expert"}) == 2
    assert waiting_requests(text, ["vllm:num_requests_running"]) == 1


# -- the test double's replicas, read as the gateway reads them ------------------------------------
class _Method:
    def __init__(self, fn: Any) -> None:
        self.fn = fn

    def remote(self) -> Any:
        return self.fn()


class _ReplicaActor:
    """Stands in for a Serve replica actor: ``record_routing_stats`` and
    ``get_num_ongoing_requests`` called with ``.remote()``, awaited."""

    def __init__(self, server: TestDoubleServer | None = None, ongoing: int = 0, dead: bool = False, hung: bool = False) -> None:
        async def stats() -> dict[str, Any]:
            if dead:
                raise RuntimeError("the actor died")
            assert server is not None
            return await server.record_routing_stats()

        async def count() -> int:
            if dead:
                raise RuntimeError("the actor died")
            if hung:  # killed, and Ray has not said so yet
                await asyncio.sleep(3600)
            return ongoing

        self.record_routing_stats = _Method(stats)
        self.get_num_ongoing_requests = _Method(count)


def _request(body: dict[str, Any]) -> Any:
    async def json() -> dict[str, Any]:
        return body

    return SimpleNamespace(method="POST", url=SimpleNamespace(path="/recap/r/0/v1/chat/completions"), json=json)


BODY = {"model": "offline/expert", "messages": [{"role": "user", "content": "hello"}]}


def test_a_test_double_replica_that_runs_one_answer_at_a_time_queues_the_rest_and_the_reader_sums_the_replicas(monkeypatch):
    calls: list[int] = []

    async def run() -> tuple[int | None, int | None]:
        a = TestDoubleServer("offline/expert", {"latency_s": 0.3, "max_running": 1})
        b = TestDoubleServer("offline/expert", {"latency_s": 0.3, "max_running": 1})

        def listed(self: Any) -> list[_ReplicaActor]:
            calls.append(1)
            return [_ReplicaActor(a), _ReplicaActor(b)]

        monkeypatch.setattr(queue_source._Replicas, "_list", listed)
        read = queue_source.queue_reader(QueueSource(kind="replica_metrics", app="recap-r-0", gauges=VLLM_WAITING))
        # 3 requests on replica a (1 runs, 2 wait), 2 on replica b (1 runs, 1 waits)
        calls_in_flight = [asyncio.ensure_future(s(_request(BODY))) for s in (a, a, a, b, b)]
        await asyncio.sleep(0.05)
        during = await read()
        replies = await asyncio.gather(*calls_in_flight)
        assert [r.status_code for r in replies] == [200] * 5
        return during, await read()

    during, after = asyncio.run(run())
    assert (during, after) == (3, 0)
    assert calls == [1]  # the replicas were listed once (again only after RELIST_S or a failure)


def test_llama_cpp_replicas_queue_is_serves_count_less_the_one_request_each_runs(monkeypatch):
    replicas = [_ReplicaActor(ongoing=3), _ReplicaActor(ongoing=1), _ReplicaActor(ongoing=0)]
    monkeypatch.setattr(queue_source._Replicas, "_list", lambda self: replicas)
    read = queue_source.queue_reader(QueueSource(kind="replica_ongoing", app="recap-r-0", running=1))

    async def run() -> int | None:
        return await read()

    assert asyncio.run(run()) == 2


def test_a_replica_that_fails_to_answer_is_left_out_and_the_replicas_are_listed_again(monkeypatch):
    listings: list[list[_ReplicaActor]] = [
        [_ReplicaActor(ongoing=4), _ReplicaActor(dead=True)],  # one replica replaced by Serve
        [_ReplicaActor(dead=True)],  # none answers: a failed read (the feed ignores it)
        [_ReplicaActor(ongoing=4), _ReplicaActor(ongoing=2)],  # the replacement is up
    ]
    monkeypatch.setattr(queue_source._Replicas, "_list", lambda self: listings.pop(0))
    read = queue_source.queue_reader(QueueSource(kind="replica_ongoing", app="recap-r-0", running=1))

    async def run() -> list[Any]:
        got: list[Any] = [await read()]
        try:
            await read()
        except RuntimeError as exc:
            got.append(str(exc))
        got += [await read(), await read()]  # listed again after the failure, then kept
        return got

    assert asyncio.run(run()) == [3, "no replica of SERVE_REPLICA::recap-r-0# answered get_num_ongoing_requests", 4, 4]
    assert listings == []


def test_a_replica_that_does_not_answer_in_time_is_left_out(monkeypatch):
    monkeypatch.setattr(queue_source, "REPLICA_TIMEOUT_S", 0.05)
    monkeypatch.setattr(queue_source._Replicas, "_list", lambda self: [_ReplicaActor(ongoing=3), _ReplicaActor(hung=True)])
    read = queue_source.queue_reader(QueueSource(kind="replica_ongoing", app="recap-r-0", running=1))

    async def run() -> int | None:
        return await asyncio.wait_for(read(), timeout=5)

    assert asyncio.run(run()) == 2


# -- the feed and the limit --------------------------------------------------------------------------
def test_a_queue_on_the_test_doubles_replicas_halves_the_limit_once_a_round_then_it_grows_back():
    now = [0.0]
    changes: list[LimitChange] = []
    texts = [
        [metrics_text("offline/expert", 2, 1), metrics_text("offline/expert", 1, 1)],  # 3 waiting
        [metrics_text("offline/expert", 0, 1), metrics_text("offline/expert", 0, 1)],  # drained
    ]

    async def read() -> int | None:
        figures = [waiting_requests(t, VLLM_WAITING) for t in texts.pop(0)]
        return sum(f for f in figures if f is not None)

    async def run() -> tuple[list[float], QueueFeed]:
        ac = adaptive_controller(now, changes, floor=2, ceiling=8)
        feed = QueueFeed(ac, read, period_s=1.0)
        tickets = [await ac.acquire(10) for _ in range(8)]
        assert await feed.poll_once() == 3 and (ac.queue, ac.queue_until) == (3, 2.0)
        limits: list[float] = []
        now[0] = 1.0
        for t in tickets[:5]:  # replies as fast as the baseline, but the replicas queue
            ac.release(t, "ok")
            limits.append(int(ac.limit))
        assert await feed.poll_once() == 0
        for t in tickets[5:]:
            ac.release(t, "ok")
            assert ac.adaptive is not None
            limits.append(ac.adaptive.limit)
        return limits, feed

    limits, feed = asyncio.run(run())
    # 8 -> 4 at the first reply; the next 3 were admitted under 8 (one round of 4 calls); the 5th
    # halves again, 4 -> 2 (the floor); drained: +1/limit a reply, 2.5, 2.9, 3.2448
    assert limits[:5] == [4, 4, 4, 4, 2]
    assert limits[5:] == pytest.approx([2.5, 2.9, 2.9 + 1 / 2.9])
    assert changes == [
        LimitChange(8, 4, "queue", 1.0, 1.0, 3),
        LimitChange(4, 2, "queue", 1.0, 1.0, 3),
        LimitChange(2, 3, "recovered", 1.0, 1.0, 0),
    ]
    assert (feed.reads, feed.failures, feed.last) == (2, 0, 0)


def test_a_stale_queue_figure_and_a_failed_read_leave_the_limit_to_its_other_signals():
    now = [0.0]
    changes: list[LimitChange] = []

    async def broken() -> int | None:
        raise ConnectionError("the replica is restarting")

    async def run() -> QueueFeed:
        ac = adaptive_controller(now, changes, floor=1, ceiling=4)
        ac.report_queue(5, fresh_s=2.0)
        feed = QueueFeed(ac, broken, period_s=1.0)
        assert await feed.poll_once() is None  # ignored: the last figure stays, and goes stale
        first = await ac.acquire(10)
        now[0] = 2.5  # past the figure's 2 s
        ac.release(first, "ok")
        assert ac.limit == 4.0
        return feed

    feed = asyncio.run(run())
    assert changes == [] and (feed.reads, feed.failures) == (1, 1)


def test_the_feed_reads_only_while_calls_are_in_flight():
    reads: list[int] = []

    async def read() -> int | None:
        reads.append(target.active)
        return 0

    target = SimpleNamespace(active=0, report_queue=lambda queue, fresh_s: None)

    async def run() -> None:
        task = asyncio.ensure_future(QueueFeed(target, read, period_s=0.02).run())
        await asyncio.sleep(0.15)
        assert reads == []  # idle: no read at all
        target.active = 2
        await asyncio.sleep(0.15)
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task

    asyncio.run(run())
    assert len(reads) >= 2 and set(reads) == {2}
