"""Memory per concurrent episode: N episodes in flight at once, PSS per episode and of the fixed actors.

Every episode is ReAct on a blocksworld instance against the fake OpenAI server answering after
200 ms, 10 calls per episode, through the real driver, episode workers, gateway and sink: the
sweep and the run are ``bench/pipeline.py``'s (``sweep_text``, ``run_one``), with N workers and
one round, the model's concurrency at least N (``sweep_text``: the gateway never queues the N episodes'
calls) and ``ray.episodes_per_process`` as asked (default: auto). While the run goes, the
driver's process tree is sampled (``bench/procstats.py``); the figures are those of the sample
with the most episode-worker memory:

* per episode = episode-worker PSS / N (the processes hosting the episodes, divided among them);
* fixed = the roles whose memory does not grow with N (``procstats.fixed_roles``: gateway,
  sink, budget, Ray's GCS, raylet, agents...); Ray's idle pre-started workers apart;
* all ran: every one of the N episodes ended, and N of them were in flight at one moment
  (from the episodes' start and end times).

    python bench/density.py                              # N = 32 64 128 256
    python bench/density.py --n 32 --episodes-per-process 1   # one process per episode, to compare

Prints a table; figures only, nothing asserted.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import threading
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")

import bench.pipeline as pipeline_bench  # noqa: E402
from bench.procstats import by_role, fixed_roles, snapshot  # noqa: E402

MB = 2**20


class Sampler:
    """Samples the run's processes every ``every_s`` seconds in a thread; keeps the sample with the
    most episode-worker PSS."""

    def __init__(self, every_s: float = 1.0) -> None:
        self.every_s = every_s
        self.peak: dict[str, tuple[int, int]] = {}
        self.fixed_peak = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)

    def _loop(self) -> None:
        while not self._stop.is_set():
            roles = by_role(snapshot(), "pss")
            if roles.get("episode worker", (0, 0))[1] >= self.peak.get("episode worker", (0, 0))[1]:
                self.peak = roles
            self.fixed_peak = max(self.fixed_peak, sum(roles[r][1] for r in fixed_roles(roles)))
            self._stop.wait(self.every_s)

    def __enter__(self) -> Sampler:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


def most_in_flight(out: Path) -> int:
    """The most episodes whose [started_at, ended_at] overlap at one moment."""
    from pipeline.store import RunStore

    eps, _ = RunStore(out).read_table("episodes", ["started_at", "ended_at"])
    marks = [(t, 1) for t in eps.column("started_at").to_pylist()] + [(t, -1) for t in eps.column("ended_at").to_pylist()]
    now = best = 0
    for _, d in sorted(marks, key=lambda m: (m[0], m[1])):  # an end before a start at the same instant
        now += d
        best = max(best, now)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[32, 64, 128, 256], help="concurrent episodes")
    ap.add_argument("--episodes-per-process", type=int, default=None, help="ray.episodes_per_process (default: auto)")
    ap.add_argument("--num-cpus", type=int, default=None)
    ap.add_argument("--by-role", action="store_true", help="print every role's PSS at each N")
    args = ap.parse_args()

    import ray

    try:
        from pipeline.worker_pool import episodes_per_process
    except ImportError:  # a checkout from before ray.episodes_per_process: one episode per process

        def episodes_per_process(workers: int, cpus: float, asked: int | None) -> int:
            return 1

    from workers.llm.offline.fake_server import FakeServer, FakeServerConfig

    # packing asked on the command line goes into the sweep; otherwise the auto rule decides
    extra = "" if args.episodes_per_process is None else f"ray: {{episodes_per_process: {args.episodes_per_process}}}\n"

    os.environ["RECAP_BENCH_KEY"] = "bench-not-a-secret"
    server = FakeServer(FakeServerConfig(latency_s=pipeline_bench.LATENCY))
    url = server.start_in_thread()
    pipeline_bench.start_ray(args.num_cpus)
    cpus = ray.cluster_resources().get("CPU", 0)
    print(
        f"host CPUs {os.cpu_count()}, Ray CPUs {cpus:.0f}; fake server latency {pipeline_bench.LATENCY * 1000:.0f} ms; "
        f"{pipeline_bench.CALLS} calls per episode; one round of N episodes"
    )
    print(
        f"{'N':>5} {'per proc':>8} {'procs':>5} {'MB/episode':>10} {'fixed MB':>8} {'idle MB':>7} {'total MB':>8} "
        f"{'in flight':>9} {'ended':>5} {'ep/min':>7}  all ran"
    )
    with tempfile.TemporaryDirectory(prefix="recap-density-") as tmp:
        for i, n in enumerate(args.n):
            k = episodes_per_process(n, cpus, args.episodes_per_process)
            with Sampler() as sampler:
                r = pipeline_bench.run_one(server, url, n, 1, 0, 10.0, Path(tmp) / str(i), extra)
            roles = sampler.peak
            procs, ep_pss = roles.get("episode worker", (0, 0))
            fixed = sum(roles[role][1] for role in fixed_roles(roles))
            idle = sum(roles.get(role, (0, 0))[1] for role in ("idle worker", "starting worker"))
            total = sum(v for _, v in roles.values())
            flight = most_in_flight(Path(tmp) / str(i) / f"w{n}")
            ran = r["episodes"] == n and flight == n
            print(
                f"{n:>5} {k:>8} {procs:>5} {ep_pss / n / MB:>10.1f} {fixed / MB:>8.0f} {idle / MB:>7.0f} {total / MB:>8.0f} "
                f"{flight:>9} {r['episodes']:>5} {r['eps_per_min']:>7.0f}  {'yes' if ran else 'NO'} "
                f"({','.join(r['reasons'])})",
                flush=True,
            )
            if args.by_role:
                for role, (count, pss) in sorted(roles.items(), key=lambda kv: -kv[1][1]):
                    print(f"      {role:<20} {count:>4} {pss / MB:>8.1f} MB")
    print(
        "MB/episode = episode-worker PSS / N at the sample with the most of it; fixed = gateway, sink, budget and\n"
        "Ray's own processes (driver, idle workers apart); total = every process of the run, driver included;\n"
        "in flight = most episodes running at one moment (from their start and end times)"
    )
    server.stop_thread()
    ray.shutdown()


if __name__ == "__main__":
    main()
