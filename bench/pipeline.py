"""Pipeline throughput: episodes per minute vs workers, sink rows per second, worker memory.

Every episode is ReAct on a blocksworld instance against the fake OpenAI server
(``workers.llm.offline.fake_server``, in a process of its own) answering after 200 ms, through the real driver, episode workers,
gateway and sink; the per-episode call limit fixes each episode at CALLS model calls, so the
ideal is ``workers x 60 / (CALLS x 0.2 s)`` episodes per minute. The series runs without a
quota; a last run repeats the largest worker count under a gateway quota, where the rate must
stop at the quota's.

    python bench/pipeline.py                               # 1 2 4 8 16 workers + quota run
    python bench/pipeline.py --workers 1 4 --rounds 3 --quota-check 0
    python bench/pipeline.py --scale                        # 8 32 64 workers, 2 rounds, no quota run

CPU ms/call sums the CPU seconds of every process of the pipeline (driver, Ray's own processes,
gateway, sink, budget, episode workers: ``bench/procstats.py``) between the end of the first round
and the last result, divided by the calls the fake server answered in that span (counted from the
server's own log); the server's process stands in for the provider: its CPU is printed apart
(``provider (not counted)`` with --by-role), never summed;
gw added ms is the median of the gateway's recorded call latency minus the server's fixed latency
(what admission, the budget, litellm and the records add to a call).

Prints a table; figures only, nothing asserted.
"""

from __future__ import annotations

import argparse
import atexit
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")

CALLS = 10
LATENCY = 0.2


def _die_with_parent() -> None:
    """In the server's process before it starts: a SIGTERM when the bench that started it dies
    (Linux ``prctl(PR_SET_PDEATHSIG)``), so a bench killed or failed never leaves it running."""
    try:
        import ctypes
        import signal

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)
    except OSError:
        pass


def start_server() -> tuple[subprocess.Popen[str], str]:
    """A fresh fake server in its own process; its base URL (``http://127.0.0.1:PORT/v1``)."""
    server = subprocess.Popen(
        [sys.executable, "-m", "workers.llm.offline.fake_server", "--port", "0", "--latency-s", str(LATENCY)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        text=True,
        preexec_fn=_die_with_parent,
    )
    assert server.stdout is not None
    line = server.stdout.readline()
    if "listening on" not in line:
        server.kill()
        raise SystemExit(f"bench: the fake server did not start ({line.strip() or 'no output'})")
    return server, line.split("listening on", 1)[1].strip()


class ServerProcess:
    """The fake server in a process of its own (``start_server``), as ``run_one`` reads it: the calls
    it answered (from its log) and its process id (its CPU is the provider's, kept out of the
    pipeline's figure)."""

    def __init__(self) -> None:
        self.process, self.url = start_server()
        self.pid = self.process.pid

    @property
    def arrivals(self) -> int:
        with urllib.request.urlopen(self.url.removesuffix("/v1") + "/fake/log", timeout=30) as resp:
            return len(json.load(resp)["calls"])

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.terminate()
            self.process.wait(10)


def sweep_text(out: Path, url: str, workers: int, units: int, rpm: int, window_s: float, extra: str = "", shards: int = 1) -> str:
    """The bench's sweep: ``workers`` episodes in flight, the model's concurrency at least that (so the
    gateway never queues them), ``shards`` gateway shards, ``extra`` YAML appended (another bench's own options)."""
    seeds = list(range((units + 8) // 9))
    quota = f"\n    rpm: {rpm}\n    window_s: {window_s}" if rpm else ""
    if shards > 1:
        quota += f"\n    gateway_shards: {shards}"
    return f"""run: bench-{workers}
output: {out}
models:
  - model: openai/fake-gpt
    api_base: {url}
    api_key_env: RECAP_BENCH_KEY
    concurrency: {max(64, workers)}{quota}
methods: [{{method: react}}]
environments: [{{benchmark: blocksworld, tasks: ["3", "4", "5"]}}]
seeds: {seeds}
limits: {{llm_calls: {CALLS}}}
workers: {workers}
{extra}"""


def run_one(
    server, url: str, workers: int, rounds: int, rpm: int, window_s: float, tmp: Path, extra: str = "", shards: int = 1
) -> dict:
    """One run of ``workers`` x ``rounds`` episodes; ``server.arrivals`` counts the calls answered so far
    (a ``ServerProcess``, or an in-thread ``FakeServer`` whose CPU is then the driver's); a server
    with a ``pid`` in the driver's process tree is taken out of the roles as the provider."""
    tmp.mkdir(parents=True, exist_ok=True)

    from pipeline.driver import Driver, Hooks, prepare
    from pipeline.gateway_backend import make_backend
    from pipeline.spec import parse_spec
    from pipeline.store import RunStore

    out = tmp / f"w{workers}"
    text = sweep_text(out, url, workers, max(workers * rounds, 4), rpm, window_s, extra, shards)
    spec = parse_spec(text)
    prepared = prepare(spec, text)
    n_units = workers * rounds
    prepared.plan.units = prepared.plan.units[:n_units]
    from bench.procstats import cpu_delta, snapshot

    # CPU and memory are read from /proc at two moments (no Ray call per result: those would be
    # counted as the pipeline's CPU): when the first round (the cold starts) is done, and at
    # the last result, before the driver tears the actors down
    marks: dict[str, tuple] = {}
    results = [0]

    def on_dispatch(unit, attempt, actor):
        pass

    def on_result(unit, attempt, out_):
        results[0] += 1
        if results[0] == workers or results[0] == n_units:
            marks["end" if "start" in marks else "start"] = (snapshot(), server.arrivals, time.monotonic())

    t0 = time.monotonic()
    summary = Driver(prepared, make_backend(spec), progress="off", hooks=Hooks(on_dispatch, on_result)).run()
    wall = time.monotonic() - t0
    eps, _ = RunStore(out).read_table("episodes", ["started_at", "ended_at", "llm_calls", "end_reason"])
    starts, ends = eps.column("started_at").to_pylist(), sorted(eps.column("ended_at").to_pylist())
    # steady state: the first round of episodes carries every process's cold start (the gateway
    # imports litellm on its first call), so rate = episodes after the first round / their span
    steady = eps.num_rows - workers
    span = ends[-1] - ends[workers - 1] if steady > 0 else ends[-1] - min(starts)
    n_measured = steady if steady > 0 else eps.num_rows
    calls = sum(eps.column("llm_calls").to_pylist()) * n_measured / eps.num_rows
    lat, _ = RunStore(out).read_table("llm_calls", ["latency_s"])
    gw_latency = statistics.median(lat.column("latency_s").to_pylist()) if lat.num_rows else float("nan")
    cpu_ms = rss_mb = float("nan")
    cpu_roles: dict[str, float] = {}
    provider_ms = float("nan")
    if "end" in marks:
        (snap0, arr0, _), (snap1, arr1, _) = marks["start"], marks["end"]
        measured_calls = max(arr1 - arr0, 1)
        provider_pid = getattr(server, "pid", None)
        if provider_pid in snap0 and provider_pid in snap1:
            provider_ms = (snap1.pop(provider_pid).cpu_s - snap0.pop(provider_pid).cpu_s) * 1000 / measured_calls
        cpu_roles = cpu_delta(snap0, snap1)
        cpu_ms = sum(cpu_roles.values()) * 1000 / measured_calls
        cpu_roles = {role: s * 1000 / measured_calls for role, s in cpu_roles.items()}
        worker_rss = [max(s.rss, snap0[pid].rss if pid in snap0 else 0) for pid, s in snap1.items() if s.role == "episode worker"]
        rss_mb = statistics.median(worker_rss) / 2**20 if worker_rss else float("nan")
    return {
        "workers": workers,
        "episodes": eps.num_rows,
        "finished": summary.finished_now,
        "span_s": span,
        "wall_s": wall,
        "eps_per_min": n_measured / span * 60,
        "calls_per_s": calls / span,
        "calls_per_episode": calls / max(n_measured, 1),
        "gw_ms": gw_latency * 1000,
        "gw_added_ms": (gw_latency - LATENCY) * 1000,
        "cpu_ms": cpu_ms,
        "cpu_roles": cpu_roles,
        "provider_ms": provider_ms,
        "call_ms": span * workers / max(calls, 1) * 1000,
        "rss_mb": rss_mb,
        "reasons": sorted(set(eps.column("end_reason").to_pylist())),
    }


def sink_rows_per_second(n_rows: int, tmp: Path, via_ray: bool) -> float:
    """Message rows (300-character contents) through the sink in batches of 500."""
    from schemas.records import MessageRecord
    from schemas.tables import record_to_row
    from workers.sink import Sink, sink_actor

    text = "You arrive at the stove. On the stove you see a pot, a pan and a potato. " * 4
    batch = [
        record_to_row(MessageRecord(f"ep{i // 50}", i % 50, "user", "observation", text[:300], i % 7), "bench")
        for i in range(500)
    ]
    folder = tmp / ("sink-ray" if via_ray else "sink")
    if via_ray:
        import ray

        sink = sink_actor().remote(str(folder), "bench", flush_rows=5000)
        ray.get(sink.stats.remote())  # the actor is up: time only the rows
        t0 = time.perf_counter()
        refs = []
        for _ in range(n_rows // 500):
            refs.append(sink.add.remote({"messages": batch}))
            if len(refs) > 8:
                ray.get(refs.pop(0))
        ray.get(refs)
        ray.get(sink.flush.remote())
        ray.kill(sink)
    else:
        t0 = time.perf_counter()
        sink = Sink(str(folder), "bench", flush_rows=5000)
        for _ in range(n_rows // 500):
            sink.add({"messages": batch})
        sink.flush()
    return n_rows / (time.perf_counter() - t0)


def start_ray(num_cpus: int | None) -> None:
    """The benches' local Ray, started again (twice at most) when its raylet misses Ray's 30 s to
    register, as happens on a loaded machine."""
    import ray

    from pipeline.raysetup import init_ray
    from pipeline.spec import RaySpec

    for tries_left in (2, 1, 0):
        try:
            init_ray(RaySpec(num_cpus=num_cpus))
            return
        except Exception as exc:
            if not tries_left or "timed out during startup" not in str(exc):
                raise
            ray.shutdown()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, nargs="+", default=None, help="worker counts (default 1 2 4 8 16; --scale: 8 32 64)")
    ap.add_argument(
        "--rounds",
        type=int,
        default=None,
        help="episodes per worker in each measurement (the first is warm-up; default 4, --scale: 2)",
    )
    ap.add_argument("--scale", action="store_true", help="the scale series of issue 37: 8 32 64 workers, 2 rounds, no quota run")
    ap.add_argument("--by-role", action="store_true", help="also print CPU ms per call of each process role")
    ap.add_argument("--rpm", type=int, default=0, help="gateway quota per window for the scaling series (0: none)")
    ap.add_argument("--window-s", type=float, default=10.0, help="quota window in seconds")
    ap.add_argument(
        "--quota-check",
        type=int,
        default=100,
        metavar="RPM",
        help="finally run the largest worker count under this quota per window (0: skip)",
    )
    ap.add_argument("--shards", type=int, default=1, help="gateway shards of the model (models[].gateway_shards)")
    ap.add_argument("--num-cpus", type=int, default=None)
    ap.add_argument("--sink-rows", type=int, default=100_000)
    args = ap.parse_args()
    if args.workers is None:
        args.workers = [8, 32, 64] if args.scale else [1, 2, 4, 8, 16]
    if args.rounds is None:
        args.rounds = 2 if args.scale else 4
    if args.scale and "--quota-check" not in sys.argv:
        args.quota_check = 0

    import ray

    os.environ["RECAP_BENCH_KEY"] = "bench-not-a-secret"
    server = ServerProcess()
    atexit.register(server.stop)  # also when Ray fails to start
    url = server.url
    start_ray(args.num_cpus)
    cpus = ray.cluster_resources().get("CPU", 0)
    print(
        f"host CPUs {os.cpu_count()}, Ray CPUs {cpus:.0f}; fake server latency {LATENCY * 1000:.0f} ms in its own process; "
        f"{CALLS} calls per episode; {args.rounds} episodes per worker (first round = warm-up, not timed)"
    )
    print(
        f"{'workers':>7} {'quota/s':>7} {'episodes':>8} {'ep/min':>8} {'ideal':>8} {'vs ideal':>8} {'vs linear':>9} "
        f"{'calls/s':>8} {'gw ms':>6} {'gw added ms':>11} {'CPU ms/call':>11} {'call ms':>7} {'worker RSS MB':>13}"
    )
    base = None
    runs = [(w, args.rpm) for w in args.workers]
    if args.quota_check:
        runs.append((max(args.workers), args.quota_check))
    with tempfile.TemporaryDirectory(prefix="recap-bench-") as tmp:
        for i, (w, rpm) in enumerate(runs):
            r = run_one(server, url, w, args.rounds, rpm, args.window_s, Path(tmp) / str(i), shards=args.shards)
            quota = rpm / args.window_s if rpm else None
            ideal = w * 60 / (CALLS * LATENCY)
            if quota:
                ideal = min(ideal, quota * 60 / CALLS)
            if base is None and not quota:
                base = r["eps_per_min"] / w
            linear = f"{r['eps_per_min'] / (base * w):>9.0%}" if base and not quota else f"{'-':>9}"
            print(
                f"{w:>7} {(f'{quota:.0f}' if quota else '-'):>7} {r['episodes']:>8} {r['eps_per_min']:>8.1f} {ideal:>8.1f} "
                f"{r['eps_per_min'] / ideal:>8.0%} {linear} {r['calls_per_s']:>8.1f} {r['gw_ms']:>6.0f} "
                f"{r['gw_added_ms']:>11.1f} {r['cpu_ms']:>11.1f} {r['call_ms']:>7.0f} {r['rss_mb']:>13.0f}  {','.join(r['reasons'])}",
                flush=True,
            )
            if args.by_role and r["cpu_roles"]:
                roles = sorted(r["cpu_roles"].items(), key=lambda kv: -kv[1])
                print(
                    "        CPU ms/call by role: "
                    + ", ".join(f"{k} {v:.1f}" for k, v in roles if v >= 0.05)
                    + f"; provider (not counted) {r['provider_ms']:.1f}",
                    flush=True,
                )
        local = sink_rows_per_second(args.sink_rows, Path(tmp), via_ray=False)
        remote = sink_rows_per_second(args.sink_rows, Path(tmp), via_ray=True)
    print(
        f"sink: {local:,.0f} rows/s in process, {remote:,.0f} rows/s through the Ray actor "
        f"(message rows of 300 characters, batches of 500)"
    )
    print(
        "ideal = workers x 60 s / (calls x latency), or the quota's rate when lower; vs linear = ep/min relative to\n"
        "1 worker x workers; gw ms = median call latency inside the gateway; gw added ms = gw ms minus the server's\n"
        "latency; CPU ms/call = CPU of all the pipeline's processes (the fake server's apart) over the measured\n"
        "span / calls the server answered in it (its own CPU: provider, not counted);\n"
        "call ms = wall time per call in a worker; worker RSS = median over the episode workers (from /proc)"
    )
    server.stop()
    ray.shutdown()


if __name__ == "__main__":
    main()
