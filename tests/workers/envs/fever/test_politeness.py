"""The per-host politeness limit is the run's, not each worker's: two Ray worker processes reading
the stand-in through the run's WikiPoliteness actor never put more than rate + burst requests in
any one second of the server's arrival log; outside Ray every environment of a process shares the
process's bucket; a bad ``wikipedia_rate`` is refused in one line, by ``recap env play`` and by
``recap run`` before anything is written."""

from __future__ import annotations

import math
import os
import time
from pathlib import Path

import pytest

from pipeline.cli import main
from pipeline.raysetup import runtime_env
from pipeline.run_services import RunServices
from pipeline.spec import SweepSpec, parse_spec
from workers.envs.fever import BENCHMARK
from workers.envs.fever.benchmark import run_limiter, wiki_source
from workers.envs.fever.ratelimit import DEFAULT_BURST, POLITENESS_VAR, TokenBucket, shared_limiter
from workers.envs.fever.standin import StandIn
from workers.envs.fever.wiki import LiveSource, WikiError, search_url

ENTITIES = ("Nikolaj Coster-Waldau", "Nikolaj", "Mercury", "Xyzzy qwerty")


def read_pages(base: str, pages: int, rate: float) -> tuple[int, str]:
    """In a Ray worker: read ``pages`` pages through the live source a FEVER environment gets at
    ``rate`` (benchmark.wiki_source); (this process's id, the limiter's class name)."""
    source = wiki_source("live", rate=rate)
    assert isinstance(source, LiveSource)
    for k in range(pages):
        source.fetch(search_url(base, ENTITIES[k % len(ENTITIES)]))
    return os.getpid(), type(source.limiter).__name__


def most_in_one_second(arrivals: list[float]) -> int:
    """The largest number of arrivals in any closed window of one second."""
    times = sorted(arrivals)
    return max(sum(1 for t in times[i:] if t <= start + 1.0) for i, start in enumerate(times))


def test_two_ray_workers_share_one_limit_per_host(ray_address):
    import ray

    from workers.envs.fever.politeness import RemoteLimiter, WikiPoliteness

    rate, pages = 2.0, 6  # 12 requests at 2/s with a burst of 2: at least 5 s however many workers
    name = f"test-wiki-politeness-{os.getpid()}"
    actor = WikiPoliteness.options(name=name).remote()  # type: ignore[attr-defined]
    env = {"env_vars": {**runtime_env()["env_vars"], POLITENESS_VAR: name}}
    reader = ray.remote(num_cpus=0)(read_pages).options(runtime_env=env)
    server = StandIn().start()
    try:
        done = ray.get([reader.remote(server.base_url, pages, rate) for _ in range(2)], timeout=120)
        host = server.base_url.split("//", 1)[1]
        stats = ray.get(actor.stats.remote())
    finally:
        server.stop()
        ray.kill(actor)
    assert len({pid for pid, _ in done}) == 2 and {cls for _, cls in done} == {"RemoteLimiter"}
    assert stats == {host: {"rate": rate, "burst": float(DEFAULT_BURST), "reservations": 12.0}}
    assert len(server.arrivals) == 12
    # each worker alone would allow rate + burst in a second: together they still do
    assert most_in_one_second(server.arrivals) <= rate + DEFAULT_BURST
    with pytest.raises(WikiError) as info:  # no such actor: the request is unavailable, never unlimited
        RemoteLimiter("no-such-politeness-actor", rate, DEFAULT_BURST).acquire(host)
    assert str(info.value) == (
        "unavailable: the run's Wikipedia rate limiter 'no-such-politeness-actor' cannot be reached (ValueError)"
    )


@pytest.mark.usefixtures("cluster_env")
def test_the_driver_starts_the_actor_only_for_a_fever_sweep():
    import ray

    def spec(benchmark: str) -> SweepSpec:
        text = f"run: r\noutput: out\nmodels:\n  - model: offline/expert\nmethods:\n  - method: react\nenvironments:\n  - benchmark: {benchmark}\n    tasks: [all]\n"
        return parse_spec(text, "sweep.yaml")

    none = RunServices.start(spec("blocksworld"), "run1", None)
    assert none.started == [] and none.worker_runtime_env() is None
    started = RunServices.start(spec("fever"), "run1", ray.get_runtime_context().get_node_id())
    ((_, name, actor),) = started.started
    assert name.startswith("recap-wiki-politeness-run1-")
    assert ray.get(ray.get_actor(name).stats.remote()) == {}
    env = started.worker_runtime_env()
    assert env is not None
    assert env["env_vars"][POLITENESS_VAR] == name and env["env_vars"]["PYTHONPATH"] == runtime_env()["env_vars"]["PYTHONPATH"]
    started.close()
    # ray.kill is asynchronous: a call sent at once may still be served; the actor is gone soon
    # after (never restarted), so a later call fails
    deadline = time.monotonic() + 60
    with pytest.raises(ray.exceptions.RayActorError):
        while time.monotonic() < deadline:
            ray.get(actor.stats.remote(), timeout=60)
            time.sleep(0.1)


def test_outside_ray_the_process_bucket_is_shared(claims_dir, monkeypatch):
    monkeypatch.delenv(POLITENESS_VAR, raising=False)
    limiter = run_limiter(3.0)
    assert isinstance(limiter, TokenBucket) and (limiter.rate, limiter.burst) == (3.0, DEFAULT_BURST)
    assert limiter is shared_limiter(3.0) is run_limiter(3.0)
    first = BENCHMARK.make("fever/1001", data_dir=str(claims_dir), wikipedia_rate=3.0)
    second = BENCHMARK.make("fever/1002", data_dir=str(claims_dir), wikipedia_rate=3.0)
    assert first.source.limiter is second.source.limiter is limiter  # type: ignore[attr-defined]


@pytest.mark.parametrize("bad", [0, -1.0, 10.5, "fast", True, math.inf])
def test_a_bad_rate_is_refused(claims_dir, bad):
    with pytest.raises(ValueError) as info:
        BENCHMARK.make("fever/1001", data_dir=str(claims_dir), wikipedia_rate=bad)
    assert str(info.value) == (
        f"wikipedia_rate must be a number of requests per second per host above 0 and at most 10, got {bad!r}"
    )


def test_env_play_and_run_refuse_a_bad_rate_in_one_line(claims_dir, tmp_path: Path, capsys):
    assert main(["env", "play", "fever/1001", "--option", f"data_dir={claims_dir}", "--option", "wikipedia_rate=0"]) == 2
    assert capsys.readouterr().err == (
        "recap: error: wikipedia_rate must be a number of requests per second per host above 0 and at most 10, got 0\n"
    )
    out = tmp_path / "out"
    spec = tmp_path / "sweep.yaml"
    spec.write_text(
        f"run: out\noutput: {out}\nmodels:\n  - model: offline/expert\nmethods:\n  - method: react\n"
        f"environments:\n  - benchmark: fever\n    tasks: [all]\n    options: {{data_dir: {claims_dir}, wikipedia_rate: 50}}\n"
    )
    assert main(["run", str(spec), "--progress", "off"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].endswith(
        "wikipedia_rate must be a number of requests per second per host above 0 and at most 10, got 50"
    )
    assert not out.exists()
