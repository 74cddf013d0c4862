"""Gateway figures: quota utilisation under 32 callers, and overhead per call vs plain litellm.

    .venv/bin/python bench/gateway.py            # both parts (about 2 minutes)
    .venv/bin/python bench/gateway.py --no-ray   # skip the Ray-actor overhead figure
    .venv/bin/python bench/gateway.py --skip-quota --calls 400   # overhead only (about 75 s)
    .venv/bin/python bench/gateway.py --shards 1 4 --callers 32  # gateway shards: 1 vs 4 on Ray

Part 1 - utilisation. A fake provider (``python -m workers.llm.offline.fake_server``, own process)
enforces RPM or TPM over a scaled window (``--window-s``, default 5 s for 60 s); 32 callers
loop through one gateway configured with the same limits. Utilisation is the provider-side
accepted rate divided by the limit's rate, measured from the first arrival to the first
arrival at least ``--windows`` windows later (exact for bursty and for smooth traffic).
Target: >= 95 % of the binding limit and 0 requests refused with 429.

Part 2 - overhead. The same fake server without limits or latency (so any latency above (a)
is ours); one caller, every path interleaved call by call: (a) ``litellm.acompletion``
directly, (b) the in-process gateway core, (c) a GatewayClient -> Ray GatewayActor with the
ledger inside it (``budget="local"``) and with a shared BudgetActor (the pipeline's path), and
(r) a bare Ray actor echoing the request, and (r2) a bare async actor that only calls litellm
(the actor hop any actor-hosted client pays: (c) - (r2) is the gateway's own part). Each gateway
path runs *before* (one inline fdatasync per reservation) and *after* (group commit,
:meth:`workers.gateway.journal.Journal.commit`), printed as p50/p95, overhead over (a), and
after/before ratios. Then ``--concurrent`` callers (default 8) at once, where group commit
shares one fdatasync among the reservations of a batch, and (b') the core alone with the HTTP
call stubbed out. Targets: (b) - (a) <= 2 ms and (c) - (a) <= 2 ms at p50.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")

from recap.llm import ChatMessage, LLMError, LLMRequest  # noqa: E402
from workers.gateway.core import DeploymentGateway  # noqa: E402
from workers.llm.litellm_setup import get_litellm  # noqa: E402
from workers.llm.providers import DeploymentConfig  # noqa: E402

MODEL = "openai/fake-gpt"


class ServerProcess:
    """The fake server in its own process (so it does not share our GIL)."""

    def __init__(self, *args: str):
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "workers.llm.offline.fake_server", "--port", "0", *args],
            cwd=REPO,
            stdout=subprocess.PIPE,
            text=True,
            env={**os.environ, "PYTHONPATH": str(REPO)},
        )
        line = self.proc.stdout.readline()  # type: ignore[union-attr]
        if "listening on" not in line:
            raise RuntimeError(f"fake server did not start: {line!r}")
        self.url = line.strip().rsplit(" ", 1)[1]

    def log(self) -> list[dict]:
        with urllib.request.urlopen(self.url.removesuffix("/v1") + "/fake/log") as r:
            return json.load(r)["calls"]

    def close(self) -> None:
        self.proc.terminate()
        self.proc.wait(10)


def request(i: int, text: str, episode: str = "bench") -> LLMRequest:
    return LLMRequest(messages=(ChatMessage("user", text),), episode_id=episode, call_index=i, purpose="bench")


def utilisation(calls: list[dict], key: str, limit: int, window_s: float, windows: int) -> float:
    accepted = sorted((c for c in calls if c["status"] == 200), key=lambda c: c["t"])
    t0 = accepted[0]["t"]
    end = next((c["t"] for c in accepted if c["t"] >= t0 + windows * window_s), None)
    if end is None:
        raise RuntimeError("run too short for the requested number of windows")
    amount = sum(1 if key == "requests" else c["counted_tokens"] for c in accepted if c["t"] < end)
    return amount * window_s / (limit * (end - t0))


async def quota_run(
    name: str,
    server_args: list[str],
    cfg_kwargs: dict,
    prompt_chars: int,
    limit: int,
    key: str,
    window_s: float,
    windows: int,
    callers: int,
) -> None:
    server = ServerProcess(*server_args, "--window-s", str(window_s))
    run_dir = Path(tempfile.mkdtemp(prefix="bench-gw-"))
    try:
        # the pad is scaled with the window like the window itself (0.25 s at 60 s)
        gw = DeploymentGateway(
            DeploymentConfig(
                model=MODEL,
                api_base=server.url,
                window_s=window_s,
                window_pad_s=0.25 * window_s / 60,
                max_concurrency=callers,
                params={"max_tokens": 50},
                **cfg_kwargs,
            ),
            run_dir=run_dir,
            run_id="bench",
        )
        stop_at = time.monotonic() + (windows + 1.5) * window_s
        failed: dict[str, int] = {}
        counter = iter(range(10**9))

        async def caller(c: int) -> None:
            while time.monotonic() < stop_at:
                i = next(counter)
                try:
                    await gw.complete(request(i, f"{i:06d} " + "kitchen step " * (prompt_chars // 13)))
                except LLMError as exc:
                    failed[exc.kind] = failed.get(exc.kind, 0) + 1

        await asyncio.gather(*[caller(c) for c in range(callers)])
        stats = gw.stats()
        await gw.aclose()
        calls = server.log()
        n429 = sum(1 for c in calls if c["status"] == 429)
        u = utilisation(calls, key, limit, window_s, windows)
        print(
            f"  {name:<14} limit {limit:>6} {key}/{window_s:g}s  utilisation {u * 100:5.1f} %  "
            f"accepted {sum(1 for c in calls if c['status'] == 200):>5}  429s {n429}  "
            f"failed calls {sum(failed.values())}  gateway 429s seen {stats['rate_limited']}"
        )
    finally:
        server.close()


def pct(xs: list[float], q: float) -> float:
    return sorted(xs)[min(len(xs) - 1, int(q * len(xs)))] * 1e3


def _line(label: str, xs: list[float], base: float | None, note: str = "") -> None:
    over = "" if base is None else f"   overhead p50 {pct(xs, 0.5) - base:+6.2f} ms"
    print(f"  {label:<34} p50 {pct(xs, 0.5):6.2f} ms  p95 {pct(xs, 0.95):6.2f} ms{over}{note}")


def _ratio(label: str, before: list[float], after: list[float], base: float) -> None:
    b, a = pct(before, 0.5) - base, pct(after, 0.5) - base
    ratio = f"{a / b:5.2f}" if a > 0 and b > 0 else "  n/a"  # an overhead at or below 0 is noise
    print(
        f"  {label:<34} overhead p50 before {b:+6.2f} ms  after {a:+6.2f} ms  after/before "
        f"{ratio}   latency p50 after/before {pct(after, 0.5) / pct(before, 0.5):5.2f}"
        f"   p95 after/before {pct(after, 0.95) / pct(before, 0.95):5.2f}"
    )


def _budget(run_dir: Path, group_commit: bool) -> object:
    from workers.gateway.ledger import BudgetLedger, LocalBudget

    return LocalBudget(BudgetLedger(run_dir), group_commit=group_commit)


async def overhead_run(n: int, use_ray: bool, callers: int) -> None:
    """Single caller, every path interleaved call by call (the machine's noise hits all paths
    alike); ``before`` = one inline fdatasync per reservation, ``after`` = group commit."""
    server = ServerProcess()
    lit = get_litellm()
    run_dir = Path(tempfile.mkdtemp(prefix="bench-gw-"))
    cfg = DeploymentConfig(model=MODEL, api_base=server.url, max_concurrency=max(8, callers), params={"max_tokens": 50})
    cores = {
        "core before": DeploymentGateway(cfg, run_dir=run_dir / "cb", run_id="bench", budget=_budget(run_dir / "cb", False)),
        "core after": DeploymentGateway(cfg, run_dir=run_dir / "ca", run_id="bench", budget=_budget(run_dir / "ca", True)),
        "core kill-safe": DeploymentGateway(cfg, run_dir=run_dir / "ck", run_id="bench", durable_reservations=False),
    }
    clients: dict[str, object] = {}
    groups: list = []
    noop = None
    if use_ray:
        import ray

        from workers.gateway.actors import RunGateways

        os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH")) if p)
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
        for name, budget, gc in (
            ("ray local before", "local", False),
            ("ray local after", "local", True),
            ("ray shared before", "shared", False),
            ("ray shared after", "shared", True),
        ):
            g = RunGateways([cfg], run_dir / name.replace(" ", "-"), "bench", budget=budget, group_commit=gc)
            groups.append(g)
            clients[name] = g.client(MODEL)
        noop = _echo_actor().remote()  # type: ignore[attr-defined]
        bare = _litellm_actor().remote(server.url)  # type: ignore[attr-defined]
    text = "Where is the onion? " * 10

    async def direct(i: int) -> None:
        await lit.acompletion(
            model=MODEL,
            api_base=server.url,
            api_key="no-key",
            timeout=120.0,
            num_retries=0,
            max_retries=0,
            max_tokens=50,
            messages=[{"role": "user", "content": f"{i} {text}"}],
        )

    labels = ["direct", *cores, *clients] + (["ray echo", "ray litellm"] if noop is not None else [])
    times: dict[str, list[float]] = {k: [] for k in labels}
    for i in range(-20, n):  # 20 warm-up rounds
        for k, label in enumerate(labels):
            req = request(100_000 * (k + 1) + i, f"{i} {text}")
            t = time.perf_counter()
            if label == "direct":
                await direct(i)
            elif label in cores:
                await cores[label].complete(req)
            elif label == "ray echo":
                await noop.echo.remote(req)  # type: ignore[union-attr]
            elif label == "ray litellm":
                await bare.complete.remote(req)  # type: ignore[union-attr]
            else:
                await clients[label].acomplete(req)  # type: ignore[attr-defined]
            if i >= 0:
                times[label].append(time.perf_counter() - t)
    for gw in cores.values():
        await gw.aclose()
    base = pct(times["direct"], 0.5)
    print(f"  -- one caller, {n} calls per path, p50/p95 latency and overhead over (a) --")
    _line("(a) litellm direct", times["direct"], None)
    _line("(b) core in process, before", times["core before"], base, "  (an inline fdatasync per reservation)")
    _line("(b) core in process, after", times["core after"], base, "  (group commit)")
    _line("(b2) core, kill-safe only", times["core kill-safe"], base, "  (reservation written, not fsync'd)")
    if noop is not None:
        _line("(r) Ray echo of the request", times["ray echo"], None, "  (a bare actor round trip)")
        _line("(r2) litellm in a bare actor", times["ray litellm"], base, "  (the actor hop alone: the floor of (c))")
        for name in clients:
            _line(f"(c) {name}", times[name], base)
    print("  -- after/before (overhead = p50 minus (a)'s p50) --")
    _ratio("(b) core in process", times["core before"], times["core after"], base)
    if noop is not None:
        _ratio("(c) Ray, gateway keeps the ledger", times["ray local before"], times["ray local after"], base)
        _ratio("(c) Ray, shared BudgetActor", times["ray shared before"], times["ray shared after"], base)
        hop50, hop95 = pct(times["ray litellm"], 0.5), pct(times["ray litellm"], 0.95)
        for name in ("ray local before", "ray local after", "ray shared before", "ray shared after"):
            print(
                f"  {name:<20} the gateway's own overhead beyond the actor hop (c) - (r2): p50 "
                f"{pct(times[name], 0.5) - hop50:+6.2f} ms  p95 {pct(times[name], 0.95) - hop95:+6.2f} ms"
            )

    if callers > 1:
        await concurrent_run(cfg, run_dir, callers, n, clients)
    for g in groups:
        g.close()
    if use_ray:
        import ray

        ray.shutdown()

    # (b') the core alone: the litellm call replaced by an instant answer
    import workers.gateway.core as core
    from workers.llm.calling import Attempt

    async def instant(kwargs):  # noqa: ANN001
        return Attempt("ok", "stop", 60, 0, 1, None)

    real = core.attempt_async
    core.attempt_async = instant
    stubs = {
        gc: DeploymentGateway(cfg, run_dir=run_dir / f"stub{gc}", run_id="bench", budget=_budget(run_dir / f"stub{gc}", gc))
        for gc in (False, True)
    }
    only: dict[bool, list[float]] = {False: [], True: []}
    for i in range(-20, n):
        for gc, stub in stubs.items():
            t = time.perf_counter()
            await stub.complete(request(30_000 + i, f"{i} {text}"))
            if i >= 0:
                only[gc].append(time.perf_counter() - t)
    for stub in stubs.values():
        await stub.aclose()
    core.attempt_async = real
    print("  -- the gateway's own work per call (HTTP stubbed out), incl. the durable reservation --")
    _line("(b') core, HTTP stubbed, before", only[False], None)
    _line("(b') core, HTTP stubbed, after", only[True], None)
    print(f"  fdatasync on this disk  p50 {fsync_p50(run_dir):6.2f} ms   (the floor of (b) - (b2))")
    server.close()


async def concurrent_run(cfg: DeploymentConfig, run_dir: Path, callers: int, n: int, clients: dict) -> None:
    """``callers`` concurrent callers: where group commit pays (one fdatasync per batch).
    Rounds alternate before/after so both see the same noise."""
    import statistics

    from workers.gateway.ledger import BudgetLedger, LocalBudget

    paths: dict[str, tuple] = {}
    for gc in (False, True):
        led = BudgetLedger(run_dir / f"conc{gc}")
        paths[f"core {'after' if gc else 'before'}"] = (
            DeploymentGateway(cfg, run_dir=run_dir / f"conc{gc}", run_id="bench", budget=LocalBudget(led, group_commit=gc)),
            led,
        )
    for name in ("ray shared before", "ray shared after"):
        if name in clients:
            paths[name] = (clients[name], None)
    lat: dict[str, list[float]] = {k: [] for k in paths}
    rate: dict[str, list[float]] = {k: [] for k in paths}
    text = "Where is the onion? " * 10
    rounds = max(3, n // 25)
    counter = iter(range(10**9))
    for r in range(rounds + 1):  # round 0 warms up
        for name, (gw, _led) in paths.items():

            async def caller() -> None:
                for _ in range(5):
                    req = request(500_000 + next(counter), f"{text} {r}")
                    t = time.perf_counter()
                    await (gw.complete(req) if name.startswith("core") else gw.acomplete(req))
                    if r:
                        lat[name].append(time.perf_counter() - t)

            t0 = time.perf_counter()
            await asyncio.gather(*[caller() for _ in range(callers)])
            if r:
                rate[name].append(callers * 5 / (time.perf_counter() - t0))
    print(f"  -- {callers} concurrent callers, {rounds} rounds of {callers * 5} calls per path --")
    for name, (_gw, led) in paths.items():
        per = None if led is None else led.stats()["journal_syncs"] / max(1, led.settled)
        syncs = "" if per is None else f"   fdatasyncs per reservation {per:4.2f}"
        print(
            f"  {name:<34} p50 {pct(lat[name], 0.5):6.2f} ms  p95 {pct(lat[name], 0.95):6.2f} ms  "
            f"calls/s median {statistics.median(rate[name]):7.1f}{syncs}"
        )
    for kind in ("core", "ray shared"):
        if f"{kind} after" in lat:
            b, a = lat[f"{kind} before"], lat[f"{kind} after"]
            print(
                f"  {kind}: latency p50 after/before {pct(a, 0.5) / pct(b, 0.5):5.2f}  p95 after/before "
                f"{pct(a, 0.95) / pct(b, 0.95):5.2f}  calls/s after/before "
                f"{statistics.median(rate[f'{kind} after']) / statistics.median(rate[f'{kind} before']):5.2f}"
            )
    for name, (gw, _led) in paths.items():
        if name.startswith("core"):
            await gw.aclose()


def _echo_actor() -> object:
    import ray

    @ray.remote(num_cpus=0)
    class Echo:
        """A bare async actor: the Ray round trip of a request, with nothing behind it."""

        async def echo(self, req: LLMRequest) -> LLMRequest:
            return req

    return Echo


def _litellm_actor() -> object:
    import ray

    @ray.remote(num_cpus=0)
    class BareLitellm:
        """litellm called from an async actor, nothing else: what any actor-hosted client pays."""

        def __init__(self, url: str):
            self.url = url
            self.lit = get_litellm()

        async def complete(self, req: LLMRequest) -> tuple:
            await self.lit.acompletion(
                model=MODEL,
                api_base=self.url,
                api_key="no-key",
                timeout=120.0,
                num_retries=0,
                max_retries=0,
                max_tokens=50,
                messages=[{"role": "user", "content": req.messages[0].content}],
            )
            return ("ok", None)

    return BareLitellm


def fsync_p50(folder: Path) -> float:
    """The cost of one fdatasync'd append, measured in the run folder's file system."""
    path = folder / "fsync-probe"
    times = []
    with open(path, "ab") as fh:
        for _ in range(100):
            t = time.perf_counter()
            fh.write(b"x" * 200 + b"\n")
            fh.flush()
            os.fdatasync(fh.fileno())
            times.append(time.perf_counter() - t)
            time.sleep(0.005)
    path.unlink()
    return pct(times, 0.5)


def shards_run(counts: list[int], callers: int, calls: int, latency_ms: float) -> None:
    """Gateway shards on Ray: ``callers`` concurrent callers (spread over the shards round robin,
    as episode workers are) through 1 vs N shards of one deployment with an RPM quota and a run
    cap far above the load (so the leases and shares are taken and renewed, never binding);
    calls/s and the latency the gateway adds over a direct litellm call."""
    import statistics

    import ray

    from workers.gateway.actors import RunGateways

    server = ServerProcess("--latency-s", str(latency_ms / 1000))
    lit = get_litellm()
    os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH")) if p)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    cfg = DeploymentConfig(
        model=MODEL, api_base=server.url, rpm=10**6, window_s=60, max_concurrency=max(16, callers), params={"max_tokens": 50}
    )
    text = "Where is the onion? " * 10

    async def direct_p50() -> float:
        xs = []
        for i in range(-10, 60):
            t = time.perf_counter()
            await lit.acompletion(
                model=MODEL,
                api_base=server.url,
                api_key="no-key",
                max_tokens=50,
                messages=[{"role": "user", "content": f"{i} {text}"}],
            )
            if i >= 0:
                xs.append(time.perf_counter() - t)
        return pct(xs, 0.5)

    base = asyncio.run(direct_p50())
    print(f"  direct litellm p50 {base:6.2f} ms (server latency {latency_ms:g} ms)")
    for n in counts:
        run_dir = Path(tempfile.mkdtemp(prefix="bench-shards-"))
        gws = RunGateways([cfg], run_dir, "bench", run_cap_usd=1000.0, budget="shared", shards=n)
        clients = [gws.client(MODEL, worker=c) for c in range(callers)]
        counter = iter(range(10**9))

        async def caller(c: int, lat: list[float], k: int) -> None:
            for _ in range(k):
                req = request(next(counter), f"{c} {text}")
                t = time.perf_counter()
                await clients[c].acomplete(req)
                lat.append(time.perf_counter() - t)

        async def rounds() -> tuple[list[float], list[float]]:
            await asyncio.gather(*[caller(c, [], 3) for c in range(callers)])  # warm-up: leases taken
            lat: list[float] = []
            rates = []
            for _ in range(3):
                t0 = time.perf_counter()
                await asyncio.gather(*[caller(c, lat, max(1, calls // callers)) for c in range(callers)])
                rates.append(callers * max(1, calls // callers) / (time.perf_counter() - t0))
            return lat, rates

        lat, rates = asyncio.run(rounds())
        stats = gws.stats()
        gws.close()
        per = stats[cfg.deployment_name]
        leases = [s.get("lease_counts", {}) for s in per.get("shards", [per])]
        local = sum(x.get("local", 0) for x in leases)
        remote = sum(x.get("remote", 0) for x in leases)
        asks = sum(x.get("asks", 0) for x in leases)
        extra = f"   reserved from a lease {local}, at the quota actor {remote}, lease asks {asks}" if n > 1 else ""
        print(
            f"  {n} shard(s)  calls/s median {statistics.median(rates):7.1f}   latency p50 {pct(lat, 0.5):6.2f} ms "
            f"p95 {pct(lat, 0.95):6.2f} ms   gw-added p50 {pct(lat, 0.5) - base:+6.2f} ms{extra}"
        )
    ray.shutdown()
    server.close()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--window-s", type=float, default=5.0)
    p.add_argument("--windows", type=int, default=4)
    p.add_argument("--callers", type=int, default=32)
    p.add_argument("--calls", type=int, default=200, help="calls per path in the overhead part")
    p.add_argument("--concurrent", type=int, default=8, help="callers of the concurrent overhead part (1: skip it)")
    p.add_argument("--no-ray", action="store_true")
    p.add_argument("--skip-quota", action="store_true")
    p.add_argument(
        "--shards", type=int, nargs="*", help="only the shards figure: 1 vs N gateway shards on Ray (e.g. --shards 1 4)"
    )
    p.add_argument("--shard-latency-ms", type=float, default=0.0, help="the fake server's latency in the shards figure")
    args = p.parse_args()
    if args.shards:
        print(f"[3] gateway shards: {args.callers} callers round robin over the shards, {args.calls} calls per round, 3 rounds")
        shards_run(args.shards, args.callers, args.calls, args.shard_latency_ms)
        return
    print(
        f"[1] quota utilisation, {args.callers} concurrent callers, window {args.window_s:g}s "
        f"(scaled from 60 s), {args.windows} windows measured"
    )
    if not args.skip_quota:
        asyncio.run(
            quota_run(
                "RPM-bound",
                ["--rpm", "60", "--tpm", "10000000"],
                {"rpm": 60, "tpm": 10_000_000},
                40,
                60,
                "requests",
                args.window_s,
                args.windows,
                args.callers,
            )
        )
        asyncio.run(
            quota_run(
                "TPM-bound",
                ["--rpm", "100000", "--tpm", "20000"],
                {"rpm": 100_000, "tpm": 20_000},
                1200,
                20_000,
                "tokens",
                args.window_s,
                args.windows,
                args.callers,
            )
        )
    print(f"[2] overhead per call, {args.calls} calls per path, interleaved; zero-latency fake server")
    asyncio.run(overhead_run(args.calls, not args.no_ray, args.concurrent))


if __name__ == "__main__":
    main()
