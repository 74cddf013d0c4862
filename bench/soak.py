"""Soak: many model calls through the real pipeline, each process's memory over time.

Why: a sweep runs for hours; a process whose memory grows by a few MB a minute (state kept
per call or per episode and never dropped) is invisible in a 30-second bench and fatal
overnight. This compresses a long sweep: ``--calls`` model calls (default 100,000) against the
fake OpenAI server (``workers.llm.offline.fake_server``) at ``--latency`` seconds per answer,
ReAct on blocksworld episodes of 10 calls each through the real driver, episode workers,
gateway, budget ledger and sink (the sweep of :mod:`bench.pipeline`). Every ``--interval``
seconds it samples the PSS of every process of the run by role (:mod:`bench.procstats`) and
the calls the server has received, and prints a row; at the end, per role, the memory after
warm-up (when 10 % of the calls were done), at the end, and the growth, and the throughput
of the first quarter of the calls against the last.

    python bench/soak.py                                   # 100,000 calls, 16 workers
    python bench/soak.py --calls 12000 --workers 8 --interval 10

What it found (issue 37; fixed): the GCS kept every task and actor call for the dashboard
(pipeline/raysetup.py SYSTEM_CONFIG), the budget ledger kept every recorded response in a dict
(workers/gateway/recorded.py), the gateway's admission windows kept every entry when the
deployment has no rpm/tpm limit (workers/gateway/limits.py), and glibc's per-thread malloc
arenas left the threaded actors' freed memory fragmented (MALLOC_ARENA_MAX in raysetup.py).

Figures only, nothing asserted. The fake server runs in a thread of this process (its
per-call log is emptied at every sample, so the driver's figure is the driver's own).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")

from bench.pipeline import CALLS, sweep_text  # noqa: E402
from bench.procstats import by_role, snapshot  # noqa: E402

#: the share of the calls after which a process counts as warmed up
WARM_FRACTION = 0.10
#: the throughput windows, as shares of the calls: the first quarter skips the cold start
#: (imports, first connections) and the last stops before the drain (fewer episodes than workers)
FIRST_QUARTER = (0.02, 0.25)
LAST_QUARTER = (0.75, 0.98)
#: the run's own actors (bench/procstats.py roles), gone once the driver has stopped
ACTOR_ROLES = ("gateway", "quota", "budget", "sink", "episode worker")


@dataclass
class Sample:
    t: float  # seconds since the run started
    calls: int  # chat requests the fake server has received
    pss: dict[str, tuple[int, int]]  # role -> (processes, PSS bytes)


@dataclass
class Series:
    samples: list[Sample] = field(default_factory=list)
    roles: list[str] = field(default_factory=list)
    #: the sample taken as the last round of episodes started (every actor still up): the end figure
    end: Sample | None = None


def _mb(n: int) -> str:
    return f"{n / 2**20:.0f}"


def _row(s: Sample, prev: Sample | None, roles: list[str]) -> str:
    rate = (s.calls - prev.calls) / max(s.t - prev.t, 1e-9) if prev else 0.0
    cells = [f"{s.t:>7.0f}", f"{s.calls:>8}", f"{rate:>7.1f}"]
    cells += [f"{_mb(s.pss.get(r, (0, 0))[1]):>{max(len(r), 6)}}" for r in roles]
    return " ".join(cells)


def _header(roles: list[str]) -> str:
    return " ".join([f"{'t s':>7}", f"{'calls':>8}", f"{'calls/s':>7}"] + [f"{r:>{max(len(r), 6)}}" for r in roles])


def time_at(samples: list[Sample], calls: float) -> float:
    """When the server had received ``calls`` requests (linear between samples)."""
    prev = samples[0]
    for s in samples:
        if s.calls >= calls:
            if s.calls == prev.calls:
                return s.t
            return prev.t + (calls - prev.calls) * (s.t - prev.t) / (s.calls - prev.calls)
        prev = s
    return samples[-1].t


def rate_between(samples: list[Sample], total: int, lo: float, hi: float) -> float:
    """Calls per second while the calls went from ``lo`` to ``hi`` (shares of ``total``)."""
    t0, t1 = time_at(samples, lo * total), time_at(samples, hi * total)
    return (hi - lo) * total / max(t1 - t0, 1e-9)


def sample_at(samples: list[Sample], calls: float) -> Sample:
    """The first sample taken once ``calls`` requests were done."""
    return next((s for s in samples if s.calls >= calls), samples[-1])


class Sampler(threading.Thread):
    """Samples the run every ``interval`` seconds and prints the row, until stopped."""

    def __init__(self, server, interval: float, series: Series):
        super().__init__(name="soak-sampler", daemon=True)
        self.server = server
        self.interval = interval
        self.series = series
        self.stopped = threading.Event()
        self.t0 = time.monotonic()
        self._lock = threading.Lock()

    def take(self) -> Sample:
        with self._lock:
            return self._take()

    def _take(self) -> Sample:
        log = self.server.log
        del log[: len(log)]  # the fake server's per-call record: bench state, not the pipeline's
        s = Sample(time.monotonic() - self.t0, self.server.arrivals, by_role(snapshot(), "pss"))
        prev = self.series.samples[-1] if self.series.samples else None
        new = [r for r in sorted(s.pss) if r not in self.series.roles]
        self.series.samples.append(s)
        if new or prev is None:
            self.series.roles += new
            print(_header(self.series.roles), flush=True)
        print(_row(s, prev, self.series.roles), flush=True)
        return s

    def run(self) -> None:
        while not self.stopped.wait(self.interval):
            self.take()


def report(series: Series, total: int) -> None:
    samples = series.samples
    warm = sample_at(samples, WARM_FRACTION * total)
    # the end figure: taken as the last round started; or, for a run cut short, the last sample
    # in which every process of the warm one was still there (after the driver stops, they go)
    actors = [(r, n) for r, (n, _) in warm.pss.items() if r in ACTOR_ROLES]
    alive = [s for s in samples if s.t >= warm.t and all(s.pss.get(r, (0, 0))[0] >= n for r, n in actors)]
    end = series.end or (alive[-1] if alive else samples[-1])
    print(
        f"\nper role: PSS MB after warm-up ({WARM_FRACTION:.0%} of the calls, t={warm.t:.0f} s) and at the end (t={end.t:.0f} s)"
    )
    print(f"{'role':<20} {'procs':>5} {'warm MB':>8} {'end MB':>8} {'growth':>7} {'MB/min':>7}")
    minutes = max(end.t - warm.t, 1e-9) / 60
    for role in series.roles:
        n0, a = warm.pss.get(role, (0, 0))
        n1, b = end.pss.get(role, (0, 0))
        growth = f"{(b - a) / a:>+7.1%}" if a else f"{'-':>7}"
        print(f"{role:<20} {n1:>5} {_mb(a):>8} {_mb(b):>8} {growth} {(b - a) / 2**20 / minutes:>+7.2f}")
    q1 = rate_between(samples, total, *FIRST_QUARTER)
    q4 = rate_between(samples, total, *LAST_QUARTER)
    print(
        f"throughput: {q1:.1f} calls/s over calls {FIRST_QUARTER[0]:.0%}-{FIRST_QUARTER[1]:.0%}, "
        f"{q4:.1f} over {LAST_QUARTER[0]:.0%}-{LAST_QUARTER[1]:.0%} ({q4 / q1 - 1:+.1%})"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=100_000, help=f"model calls in all (episodes of {CALLS} calls)")
    ap.add_argument("--workers", type=int, default=16, help="episode workers (episodes in flight)")
    ap.add_argument("--latency", type=float, default=0.05, help="the fake server's answer time, seconds")
    ap.add_argument("--interval", type=float, default=10.0, help="seconds between samples")
    ap.add_argument("--num-cpus", type=int, default=None)
    args = ap.parse_args()
    if args.calls < CALLS or args.workers < 1 or args.latency < 0 or args.interval <= 0:
        ap.error(f"--calls must be at least {CALLS}, --workers at least 1, --latency >= 0, --interval > 0")

    from pipeline.driver import Driver, Hooks, prepare
    from pipeline.gateway_backend import make_backend
    from pipeline.raysetup import init_ray, shutdown_ray
    from pipeline.spec import RaySpec, parse_spec
    from workers.llm.offline.fake_server import FakeServer, FakeServerConfig

    os.environ["RECAP_BENCH_KEY"] = "bench-not-a-secret"
    episodes = math.ceil(args.calls / CALLS)
    server = FakeServer(FakeServerConfig(latency_s=args.latency))
    url = server.start_in_thread()
    init_ray(RaySpec(num_cpus=args.num_cpus))
    series = Series()
    with tempfile.TemporaryDirectory(prefix="recap-soak-") as tmp:
        out = Path(tmp) / "soak"
        text = sweep_text(out, url, args.workers, episodes, 0, 10.0)
        spec = parse_spec(text)
        prepared = prepare(spec, text)
        if len(prepared.plan.units) < episodes:
            sys.exit(f"soak: the sweep has {len(prepared.plan.units)} units, {episodes} needed")
        prepared.plan.units = prepared.plan.units[:episodes]
        print(
            f"soak: {episodes} episodes x {CALLS} calls, {args.workers} workers, fake server {args.latency * 1000:.0f} ms "
            f"(ideal {args.workers / args.latency:.0f} calls/s), a sample every {args.interval:.0f} s",
            flush=True,
        )
        sampler = Sampler(server, args.interval, series)
        done = [0]
        last_round = max(episodes - args.workers, 1)

        def on_result(unit, attempt, outcome) -> None:
            # the end figure: taken as the last round starts, while every actor is still up
            # (after the driver returns its actors are gone)
            done[0] += 1
            if done[0] == last_round:
                series.end = sampler.take()

        sampler.take()
        sampler.start()
        try:
            summary = Driver(prepared, make_backend(spec), progress="off", hooks=Hooks(None, on_result)).run()
        finally:
            sampler.stopped.set()
            sampler.join()
        print(f"episodes finished: {summary.finished_now}")
    report(series, server.arrivals)
    server.stop_thread()
    shutdown_ray()


if __name__ == "__main__":
    main()
