"""Gateway figures: quota utilisation under 32 callers, and overhead per call vs plain litellm.

    .venv/bin/python bench/gateway.py            # both parts (about 2 minutes)
    .venv/bin/python bench/gateway.py --no-ray   # skip the Ray-actor overhead figure

Part 1 - utilisation. A fake provider (``python -m workers.llm.fake_server``, own process)
enforces RPM or TPM over a scaled window (``--window-s``, default 5 s for 60 s); 32 callers
loop through one gateway configured with the same limits. Utilisation is the provider-side
accepted rate divided by the limit's rate, measured from the first arrival to the first
arrival at least ``--windows`` windows later (exact for bursty and for smooth traffic).
Target: >= 95 % of the binding limit and 0 requests refused with 429.

Part 2 - overhead. One caller, the same fake server without limits or latency; interleaved
calls through (a) ``litellm.acompletion`` directly, (b) the in-process gateway core,
(c) a GatewayClient -> Ray GatewayActor (+ BudgetActor). Reports p50 latencies and the
gateway's overhead over (a); also (b') the core alone with the HTTP call stubbed out.
Target: (b) - (a) <= 2 ms at p50.
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
        self.proc = subprocess.Popen([sys.executable, "-m", "workers.llm.fake_server", "--port", "0", *args],
                                     cwd=REPO, stdout=subprocess.PIPE, text=True,
                                     env={**os.environ, "PYTHONPATH": str(REPO)})
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


async def quota_run(name: str, server_args: list[str], cfg_kwargs: dict, prompt_chars: int, limit: int,
                    key: str, window_s: float, windows: int, callers: int) -> None:
    server = ServerProcess(*server_args, "--window-s", str(window_s))
    run_dir = Path(tempfile.mkdtemp(prefix="bench-gw-"))
    try:
        # the pad is scaled with the window like the window itself (0.25 s at 60 s)
        gw = DeploymentGateway(DeploymentConfig(model=MODEL, api_base=server.url, window_s=window_s,
                                                window_pad_s=0.25 * window_s / 60, max_concurrency=callers,
                                                params={"max_tokens": 50}, **cfg_kwargs),
                               run_dir=run_dir, run_id="bench")
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
        print(f"  {name:<14} limit {limit:>6} {key}/{window_s:g}s  utilisation {u * 100:5.1f} %  "
              f"accepted {sum(1 for c in calls if c['status'] == 200):>5}  429s {n429}  "
              f"failed calls {sum(failed.values())}  gateway 429s seen {stats['rate_limited']}")
    finally:
        server.close()


def pct(xs: list[float], q: float) -> float:
    return sorted(xs)[min(len(xs) - 1, int(q * len(xs)))] * 1e3


async def overhead_run(n: int, use_ray: bool) -> None:
    server = ServerProcess()
    lit = get_litellm()
    run_dir = Path(tempfile.mkdtemp(prefix="bench-gw-"))
    cfg = DeploymentConfig(model=MODEL, api_base=server.url, max_concurrency=8, params={"max_tokens": 50})
    gw = DeploymentGateway(cfg, run_dir=run_dir / "core", run_id="bench")
    gw_kill_safe = DeploymentGateway(cfg, run_dir=run_dir / "core2", run_id="bench", durable_reservations=False)
    client = None
    if use_ray:
        import ray

        from workers.gateway.actors import RunGateways

        os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH")) if p)
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
        gws = RunGateways([cfg], run_dir / "ray", "bench")
        client = gws.client(MODEL)
    text = "Where is the onion? " * 10

    async def direct(i: int) -> None:
        await lit.acompletion(model=MODEL, api_base=server.url, api_key="no-key", timeout=120.0,
                              num_retries=0, max_retries=0, max_tokens=50,
                              messages=[{"role": "user", "content": f"{i} {text}"}])

    times: dict[str, list[float]] = {"a": [], "b": [], "b2": [], "c": []}
    for i in range(-20, n):  # 20 warm-up rounds
        for label in ("a", "b", "b2", "c") if client else ("a", "b", "b2"):
            t = time.perf_counter()
            if label == "a":
                await direct(i)
            elif label == "b":
                await gw.complete(request(10_000 + i, f"{i} {text}"))
            elif label == "b2":
                await gw_kill_safe.complete(request(10_000 + i, f"{i} {text}"))
            else:
                await client.acomplete(request(20_000 + i, f"{i} {text}"))
            if i >= 0:
                times[label].append(time.perf_counter() - t)
    await gw.aclose()
    await gw_kill_safe.aclose()

    # (b') the core alone: the litellm call replaced by an instant answer
    import workers.gateway.core as core
    from workers.llm.calling import Attempt

    async def instant(kwargs):  # noqa: ANN001
        return Attempt("ok", "stop", 60, 0, 1, None)

    real = core.attempt_async
    core.attempt_async = instant
    stub = DeploymentGateway(cfg, run_dir=run_dir / "stub", run_id="bench")
    only: list[float] = []
    for i in range(-20, n):
        t = time.perf_counter()
        await stub.complete(request(30_000 + i, f"{i} {text}"))
        if i >= 0:
            only.append(time.perf_counter() - t)
    await stub.aclose()
    core.attempt_async = real

    a50, b50 = pct(times["a"], 0.5), pct(times["b"], 0.5)
    print(f"  (a) litellm direct      p50 {a50:6.2f} ms  p90 {pct(times['a'], 0.9):6.2f} ms")
    b2 = pct(times["b2"], 0.5)
    print(f"  (b) gateway core        p50 {b50:6.2f} ms  p90 {pct(times['b'], 0.9):6.2f} ms"
          f"   overhead p50 {b50 - a50:+.2f} ms  (default: reservation fsync'd before sending)")
    print(f"  (b2) core, kill-safe    p50 {b2:6.2f} ms  p90 {pct(times['b2'], 0.9):6.2f} ms"
          f"   overhead p50 {b2 - a50:+.2f} ms  (durable_reservations=False: written, not fsync'd)")
    if client:
        c50 = pct(times["c"], 0.5)
        print(f"  (c) Ray GatewayClient   p50 {c50:6.2f} ms  p90 {pct(times['c'], 0.9):6.2f} ms"
              f"   overhead p50 {c50 - a50:+.2f} ms")
        gws.close()
        ray.shutdown()
    print(f"  (b') core, HTTP stubbed p50 {pct(only, 0.5):6.2f} ms  p90 {pct(only, 0.9):6.2f} ms"
          "   (the gateway's own work per call, incl. the fsync'd reservation)")
    print(f"  fdatasync on this disk  p50 {fsync_p50(run_dir):6.2f} ms   (the floor of (b) - (b2))")
    server.close()


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


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--window-s", type=float, default=5.0)
    p.add_argument("--windows", type=int, default=4)
    p.add_argument("--callers", type=int, default=32)
    p.add_argument("--calls", type=int, default=200, help="calls per path in the overhead part")
    p.add_argument("--no-ray", action="store_true")
    p.add_argument("--skip-quota", action="store_true")
    args = p.parse_args()
    print(f"[1] quota utilisation, {args.callers} concurrent callers, window {args.window_s:g}s "
          f"(scaled from 60 s), {args.windows} windows measured")
    if not args.skip_quota:
        asyncio.run(quota_run("RPM-bound", ["--rpm", "60", "--tpm", "10000000"], {"rpm": 60, "tpm": 10_000_000},
                              40, 60, "requests", args.window_s, args.windows, args.callers))
        asyncio.run(quota_run("TPM-bound", ["--rpm", "100000", "--tpm", "20000"], {"rpm": 100_000, "tpm": 20_000},
                              1200, 20_000, "tokens", args.window_s, args.windows, args.callers))
    print(f"[2] overhead per call, 1 caller, {args.calls} calls per path, interleaved")
    asyncio.run(overhead_run(args.calls, not args.no_ray))


if __name__ == "__main__":
    main()
