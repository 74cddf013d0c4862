"""Benchmark: FEVER's Wikipedia access - pages per second per worker through the shared politeness
limit, and snapshot replay speed, against the stand-in server (no network).

    .venv/bin/python bench/fever.py [--workers 4] [--pages 12] [--rate 2.0] [--burst 2] [--replays 200]

Why ratios: the machine is shared, so absolute figures drift from run to run; each figure is
printed beside the one it is compared with, both measured in this run. ``--workers`` threads
share one per-host limiter (what every FEVER environment of a worker process shares) and each
searches ``--pages`` pages on the stand-in (workers/envs/fever/standin.py, a test double serving
Wikipedia-shaped HTML on the loopback): the limited rate against the limit (should be close to
1.0 once the burst is spent), per worker, and against the server's unlimited rate. Then the pages
read are written as a ``wiki_pages`` table and replayed ``--replays`` times from a snapshot
(:class:`workers.envs.fever.pages.Snapshot`): snapshot pages per second against the live ones.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from workers.envs.fever.pages import MemoryPageStore, Snapshot, write_pages  # noqa: E402
from workers.envs.fever.ratelimit import TokenBucket  # noqa: E402
from workers.envs.fever.standin import StandIn  # noqa: E402
from workers.envs.fever.wiki import LiveSource, SnapshotSource, search_url  # noqa: E402

#: searches the stand-in answers with a page (an article, result lists, a disambiguation, a missing page)
ENTITIES = ("Nikolaj Coster-Waldau", "Nikolaj", "Mercury", "[Mercury]", "Xyzzy qwerty")


def _live(base: str, workers: int, pages: int, limiter: TokenBucket, store: MemoryPageStore) -> float:
    """Wall seconds for ``workers`` threads to read ``pages`` pages each through ``limiter``."""
    sources = [LiveSource(store, limiter=limiter) for _ in range(workers)]

    def read(source: LiveSource) -> None:
        for k in range(pages):
            source.fetch(search_url(base, ENTITIES[k % len(ENTITIES)]))

    threads = [threading.Thread(target=read, args=(s,)) for s in sources]
    start = time.perf_counter()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return time.perf_counter() - start


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
    ap.add_argument("--workers", type=int, default=4)
    ap.add_argument("--pages", type=int, default=12, help="pages each worker reads")
    ap.add_argument("--rate", type=float, default=2.0, help="the shared limit, requests per second per host")
    ap.add_argument("--burst", type=int, default=2)
    ap.add_argument("--replays", type=int, default=200)
    args = ap.parse_args(argv)
    total = args.workers * args.pages
    server = StandIn().start()
    try:
        store = MemoryPageStore()
        free = _live(server.base_url, args.workers, args.pages, TokenBucket(1e9, 10**9), store)
        limited = _live(server.base_url, args.workers, args.pages, TokenBucket(args.rate, args.burst), MemoryPageStore())
    finally:
        server.stop()
    free_rate, limited_rate = total / free, total / limited
    # the bucket allows `burst` at once, then `rate` per second: the ideal time for `total` requests
    ideal = max(0.0, (total - args.burst) / args.rate)
    print(f"load average {os.getloadavg()[0]:.2f}; {args.workers} workers x {args.pages} pages on the stand-in")
    print(f"unlimited:       {free_rate:8.1f} pages/s in all, {free_rate / args.workers:8.1f} per worker")
    print(
        f"shared limit:    {limited_rate:8.2f} pages/s in all, {limited_rate / args.workers:8.2f} per worker "
        f"(limit {args.rate:g}/s, burst {args.burst})"
    )
    print(f"  limited time / ideal time under the limit: {limited / ideal:.3f}" if ideal else "")
    print(f"  limited rate / unlimited rate: {limited_rate / free_rate:.4f}")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        write_pages(store.records, folder / "wiki_pages.parquet")
        urls = sorted({r.url for r in store.records})
        load_s, replay_s = _replay(folder, urls, args.replays)
    replay_rate = len(urls) * args.replays / replay_s
    print(f"snapshot: {len(urls)} distinct pages loaded in {load_s * 1000:.1f} ms; {replay_rate:,.0f} answers/s")
    print(f"  snapshot answers/s / unlimited live pages/s: {replay_rate / free_rate:,.0f}x")
    print(f"  snapshot answers/s / limited live pages/s:   {replay_rate / limited_rate:,.0f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
