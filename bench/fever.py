"""Benchmark: FEVER's Wikipedia access - pages per second per worker through the run's shared
politeness limit with Ray workers, and snapshot replay speed, against the stand-in server (no network).

    .venv/bin/python bench/fever.py [--workers 2] [--pages 8] [--rate 2.0] [--burst 2] [--replays 200]

Why ratios: the machine is shared, so absolute figures drift from run to run; each figure is
printed beside the one it is compared with, both measured in this run. ``--workers`` Ray worker
processes each search ``--pages`` pages on the stand-in (workers/envs/fever/standin.py, a test
double serving Wikipedia-shaped HTML on the loopback) through the limiter a FEVER environment
gets (``benchmark.run_limiter``): first through the run's WikiPoliteness actor (what a sweep's
workers share), then with a bucket per worker process (what they had before: ``workers`` times
the rate). The rates come from the server's log of arrival times: the arrival span against the
ideal span under the limit, ``(requests - burst) / rate`` (1.0: the limit holds for the run; 1 /
workers: it holds per worker only). Beside them: one actor reservation's round trip against one
unlimited page read. Then the pages read are written as a ``wiki_pages`` table and replayed
``--replays`` times from a snapshot (:class:`workers.envs.fever.pages.Snapshot`): snapshot pages
per second against the live ones.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import ray  # noqa: E402

from pipeline.raysetup import init_ray, runtime_env, shutdown_ray  # noqa: E402
from pipeline.spec import RaySpec  # noqa: E402
from workers.envs.fever.benchmark import run_limiter  # noqa: E402
from workers.envs.fever.pages import MemoryPageStore, Snapshot, write_pages  # noqa: E402
from workers.envs.fever.politeness import WikiPoliteness  # noqa: E402
from workers.envs.fever.ratelimit import POLITENESS_VAR, TokenBucket  # noqa: E402
from workers.envs.fever.standin import StandIn  # noqa: E402
from workers.envs.fever.wiki import LiveSource, SnapshotSource, search_url  # noqa: E402

#: searches the stand-in answers with a page (an article, result lists, a disambiguation, a missing page)
ENTITIES = ("Nikolaj Coster-Waldau", "Nikolaj", "Mercury", "[Mercury]", "Xyzzy qwerty")


def _read(base: str, pages: int, rate: float, burst: int) -> str:
    """In a Ray worker: read ``pages`` pages through the limiter a FEVER environment gets; its class name."""
    source = LiveSource(None, limiter=run_limiter(rate, burst))
    for k in range(pages):
        source.fetch(search_url(base, ENTITIES[k % len(ENTITIES)]))
    return type(source.limiter).__name__


def _ray_live(workers: int, pages: int, rate: float, burst: int, actor_name: str | None) -> tuple[float, str]:
    """(seconds between the first and last arrival at a fresh stand-in, the workers' limiter) for
    ``workers`` Ray worker processes reading ``pages`` pages each; ``actor_name``: the run's actor, or
    None for a bucket per process."""
    env_vars = dict(runtime_env()["env_vars"])
    if actor_name is not None:
        env_vars[POLITENESS_VAR] = actor_name
    reader: Any = ray.remote(num_cpus=0)(_read)
    server = StandIn().start()
    try:
        kinds = ray.get(
            [
                reader.options(runtime_env={"env_vars": env_vars}).remote(server.base_url, pages, rate, burst)
                for _ in range(workers)
            ]
        )
    finally:
        server.stop()
    return max(server.arrivals) - min(server.arrivals), "+".join(sorted(set(kinds)))


def _unlimited(base: str, pages: int, store: MemoryPageStore) -> float:
    """Seconds for one reader to read ``pages`` pages with no limit (the server's own speed)."""
    source = LiveSource(store, limiter=TokenBucket(1e9, 10**9))
    start = time.perf_counter()
    for k in range(pages):
        source.fetch(search_url(base, ENTITIES[k % len(ENTITIES)]))
    return time.perf_counter() - start


def _reserve_s(actor: Any, n: int = 200) -> float:
    """Seconds per reservation round trip to the actor (a host of its own, so nothing waits)."""
    start = time.perf_counter()
    for _ in range(n):
        ray.get(actor.reserve.remote("bench.invalid", 1e9, 10**9))
    return (time.perf_counter() - start) / n


def _replay(folder: Path, urls: list[str], replays: int) -> tuple[float, float]:
    """(seconds to load the snapshot, seconds to answer every URL ``replays`` times from it)."""
    start = time.perf_counter()
    source = SnapshotSource(Snapshot(folder))
    loaded = time.perf_counter()
    for _ in range(replays):
        for url in urls:
            source.fetch(url)
    return loaded - start, time.perf_counter() - loaded


def main(argv: list[str] | None = None) -> int:
    """Run the measurements and print them."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2, help="Ray worker processes")
    ap.add_argument("--pages", type=int, default=8, help="pages each worker reads")
    ap.add_argument("--rate", type=float, default=2.0, help="the shared limit, requests per second per host")
    ap.add_argument("--burst", type=int, default=2)
    ap.add_argument("--replays", type=int, default=200)
    args = ap.parse_args(argv)
    total = args.workers * args.pages
    started = init_ray(RaySpec(num_cpus=2))
    try:
        name = f"bench-wiki-politeness-{os.getpid()}"
        actor: Any = WikiPoliteness
        actor = actor.options(name=name).remote()
        shared_s, shared_kind = _ray_live(args.workers, args.pages, args.rate, args.burst, name)
        apart_s, apart_kind = _ray_live(args.workers, args.pages, args.rate, args.burst, None)
        reserve_s = _reserve_s(actor)
        ray.kill(actor)
    finally:
        if started:
            shutdown_ray()
    store = MemoryPageStore()
    server = StandIn().start()
    try:
        free = _unlimited(server.base_url, total, store)
    finally:
        server.stop()
    free_rate = total / free
    # the bucket allows `burst` at once, then `rate` per second: the ideal arrival span for `total` requests
    ideal = max(0.0, (total - args.burst) / args.rate)
    print(f"load average {os.getloadavg()[0]:.2f}; {args.workers} Ray workers x {args.pages} pages on the stand-in")
    print(f"unlimited (one reader): {free_rate:8.1f} pages/s")
    for label, span, kind in (("shared limit", shared_s, shared_kind), ("bucket per worker", apart_s, apart_kind)):
        rate = (total - args.burst) / span if span else float("inf")
        print(
            f"{label + ' (' + kind + ')':32} {rate:6.2f} pages/s in all, {rate / args.workers:6.2f} per worker "
            f"(limit {args.rate:g}/s, burst {args.burst}); arrival span / ideal span: {span / ideal:.3f}"
        )
    print(f"  shared-limit rate / per-worker-bucket rate: {apart_s / shared_s:.3f}")
    print(f"  actor reservation round trip / unlimited page read: {reserve_s / (1 / free_rate):.3f} ({reserve_s * 1000:.2f} ms)")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        write_pages(store.records, folder / "wiki_pages.parquet")
        urls = sorted({r.url for r in store.records})
        load_s, replay_s = _replay(folder, urls, args.replays)
    replay_rate = len(urls) * args.replays / replay_s
    shared_rate = (total - args.burst) / shared_s
    print(f"snapshot: {len(urls)} distinct pages loaded in {load_s * 1000:.1f} ms; {replay_rate:,.0f} answers/s")
    print(f"  snapshot answers/s / unlimited live pages/s: {replay_rate / free_rate:,.0f}x")
    print(f"  snapshot answers/s / shared-limit live pages/s: {replay_rate / shared_rate:,.0f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
