"""Provider faults through the whole pipeline: each handled by its class, bounded, visible.

The fake server injects faults into a real sweep (driver, workers, gateway actors):

* transient: random 500/502/503, empty and malformed bodies and hung connections, plus two
  bursts in which every request gets a 503 - retried with backoff (``server_error``) or cut at
  the attempt timeout and charged at worst case (``timeout``);
* context length: prompts past the model's window answer 400 ``context_length_exceeded`` -
  never retried by the gateway; the agent drops its oldest messages and asks again;
* a 429 storm: every request refused for ``storm_s`` seconds (Retry-After 1 s) - the gateway
  shrinks its concurrency and pauses; with enough retries every call outlives the storm, with
  the default retries calls give up after exactly ``retries + 1`` attempts.

"Handled by its class": each failed attempt the server logged matches one gateway ``events``
row of the right class (``retry`` or ``call_failed``); "bounded": no call made more attempts
than its deployment allows and the server saw exactly the attempts the ``llm_calls`` rows
account for; every unit still ends with exactly one terminal row.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any

from tests.pipeline.chaos.harness import (
    Lab,
    ScenarioResult,
    blocks,
    events,
    fake_model,
    journal,
    rows,
    run_driver,
    sweep,
    terminal,
)

#: the error class each fault mode of the fake server must be handled as
CLASS_OF_MODE = {
    "500": "server_error",
    "502": "server_error",
    "503": "server_error",
    "empty": "server_error",
    "malformed": "server_error",
    "hang": "timeout",
    "429": "rate_limit",
    "ctx": "context_length",
}


def _fault_accounting(res: ScenarioResult, out: Path, server: Any, max_attempts: int) -> Counter:
    """Server-side failed attempts == gateway events of the same class; attempts bounded."""
    arrivals = Counter(CLASS_OF_MODE[c.mode] for c in server.log if c.mode in CLASS_OF_MODE)
    gw = [e for e in events(out) if e["source"] == "gateway" and e["kind"] in ("retry", "call_failed")]
    seen = Counter(e["detail"]["kind"] for e in gw)
    res.check(
        "every failed attempt is one gateway event of its class",
        arrivals == seen,
        f"server {dict(arrivals)} vs events {dict(seen)}",
    )
    calls = [r for r in rows(out, "llm_calls") if r["error_kind"] != "budget"]
    over = [r["call_key"] for r in calls if r["retries"] > max_attempts - 1]
    res.check(f"no call made more than {max_attempts} attempts", not over, over[:3])
    sent = sum(r["retries"] + 1 for r in calls if r["served_from"] == "provider")
    res.check(
        "server arrivals == attempts the llm_calls rows account for", sent == len(server.log), f"{sent} vs {len(server.log)}"
    )
    gave_up = [r for r in calls if r["status"] == "error" and r["error_kind"] in ("server_error", "timeout", "rate_limit")]
    early = [r["call_key"] for r in gave_up if r["retries"] != max_attempts - 1]
    res.check("a transient failure gives up only after every attempt", not early, early[:3])
    return arrivals


def _units_done(res: ScenarioResult, out: Path) -> None:
    term = terminal(out)
    res.lost += len(term.lost)
    res.duplicated += term.duplicated
    res.check("one terminal row per unit", not term.lost and term.duplicated == 0, (len(term.lost), term.duplicated))


def _transient(lab: Lab, res: ScenarioResult) -> None:
    res.begin_run()
    faults = {"500": 0.06, "502": 0.03, "503": 0.03, "empty": 0.04, "malformed": 0.04, "hang": 0.08}
    server = lab.server(latency_s=0.05, prefix_memory=0, fault_rates=dict(faults), hang_s=20.0, seed=lab.seed)
    out = lab.folder("faults-transient") / "run"
    retries = 6
    text = sweep(out, fake_model(server.base_url, retries=retries, timeout_s=1.0), blocks(12), llm_calls=6, workers=3)
    stop = threading.Event()

    def bursts() -> None:  # two 1.5 s windows in which every request gets a 503
        for _ in range(2):
            if stop.wait(4.0):
                return
            server.config.fault_rates = {"503": 1.0}
            time.sleep(1.5)
            server.config.fault_rates = dict(faults)

    t = threading.Thread(target=bursts, daemon=True)
    t.start()
    t0 = time.monotonic()
    summary, _ = run_driver(text)
    stop.set()
    t.join(10)
    wall = time.monotonic() - t0
    res.check("the run ends (exit 0)", summary.exit_code() == 0, summary.exit_code())
    arrivals = _fault_accounting(res, out, server, retries + 1)
    res.check("every fault class occurred", {"server_error", "timeout"} <= set(arrivals), dict(arrivals))
    charged = [e for e in journal(out) if e.get("status") == "charged"]
    # a hang may have been billed, and so may a 200 we could not read (empty, malformed body)
    unreadable = sum(1 for c in server.log if c.mode in ("empty", "malformed"))
    res.check(
        "each timed-out attempt and each unreadable 200 charged at worst case",
        len(charged) == arrivals["timeout"] + unreadable,
        f"{len(charged)} charged vs {arrivals['timeout']} hangs + {unreadable} unreadable replies",
    )
    _units_done(res, out)
    eps = rows(out, "episodes")
    failed = sum(1 for r in eps if r["end_reason"] == "llm_error")
    res.notes.append(
        f"transient: {sum(arrivals.values())} faults in {len(server.log)} requests "
        f"({', '.join(f'{k} {v}' for k, v in sorted(arrivals.items()))}), {failed}/{len(eps)} episodes "
        f"ended llm_error, {wall:.0f}s"
    )
    res.end_run()


def _context_length(lab: Lab, res: ScenarioResult) -> None:
    res.begin_run()
    probe = lab.server(prefix_memory=0)
    calib = lab.folder("faults-ctx") / "calibrate"
    run_driver(sweep(calib, fake_model(probe.base_url), blocks(1), llm_calls=8, workers=1))
    prompts = sorted(r["prompt_tokens"] for r in rows(calib, "llm_calls"))
    # the window fits the first three prompts: later ones must be cut down by the agent
    window = prompts[2] + 64 + 4
    server = lab.server(prefix_memory=0, max_context_tokens=window)
    out = lab.folder("faults-ctx") / "run"
    summary, _ = run_driver(sweep(out, fake_model(server.base_url), blocks(6), llm_calls=10, workers=3))
    res.check("the run ends (exit 0)", summary.exit_code() == 0, summary.exit_code())
    arrivals = _fault_accounting(res, out, server, 6)
    ctx = [r for r in rows(out, "llm_calls") if r["error_kind"] == "context_length"]
    res.check(
        "context-length errors occurred, never retried by the gateway", ctx and all(r["retries"] == 0 for r in ctx), len(ctx)
    )
    by_episode: dict[str, list[dict[str, Any]]] = {}
    for r in rows(out, "llm_calls"):
        by_episode.setdefault(r["episode_id"], []).append(r)
    recovered = 0
    for calls in by_episode.values():
        calls.sort(key=lambda r: r["call_index"])
        for a, b in zip(calls, calls[1:]):
            if a["error_kind"] == "context_length" and b["status"] == "ok":
                recovered += 1
    res.check("the agent recovered: the next call after the error succeeded", recovered >= 1, recovered)
    _units_done(res, out)
    res.notes.append(
        f"context length: {arrivals['context_length']} refusals at {window} tokens, {recovered} recovered by dropping messages"
    )
    res.end_run()


def provider_faults(lab: Lab) -> ScenarioResult:
    """Transient faults (5xx, bursts, hangs, empty/malformed bodies) and context-length errors."""
    res = ScenarioResult("provider faults: 5xx, hangs, bodies, context")
    lab.ray_address()
    _transient(lab, res)
    _context_length(lab, res)
    return res


# --------------------------------------------------------------------------------------------
def _storm_run(lab: Lab, res: ScenarioResult, name: str, storm_s: float, retries: int | None, workers: int) -> None:
    from pipeline.gateway_backend import GatewayBackend
    from pipeline.spec import parse_spec

    res.begin_run()
    server = lab.server(latency_s=0.05, prefix_memory=0)
    out = lab.folder(name) / "run"
    transport = {"retries": retries} if retries is not None else {}
    text = sweep(out, fake_model(server.base_url, **transport), blocks(6), llm_calls=4, workers=workers)
    backend = GatewayBackend(parse_spec(text))
    storm: dict[str, float] = {}
    low = {"limit": 10**9, "shrinks": 0, "paused": 0}

    def weather() -> None:
        import ray

        while not server.log:  # the storm starts with the first request
            time.sleep(0.01)
        server.config.fault_rates = {"429": 1.0}
        storm["start"] = time.monotonic()
        while time.monotonic() - storm["start"] < storm_s:
            try:
                s = ray.get(next(iter(backend.actors.values())).stats.remote(), timeout=5)
                low["limit"] = min(low["limit"], s["concurrency_limit"])
                low["shrinks"] = max(low["shrinks"], s["shrinks"])
                low["paused"] += int(s["retry_after_pause_s"] > 0)
            except Exception:
                pass
            time.sleep(0.25)
        server.config.fault_rates = {}
        storm["end"] = time.monotonic()

    t = threading.Thread(target=weather, daemon=True)
    t.start()
    summary, _ = run_driver(text, backend=backend)
    t.join(storm_s + 30)
    max_attempts = (retries if retries is not None else 5) + 1
    refused = [c for c in server.log if c.mode == "429"]
    res.check("the storm lasted its length", storm.get("end", 0) - storm.get("start", 0) >= storm_s - 0.01, storm)
    _fault_accounting(res, out, server, max_attempts)
    # one request per worker may be in flight when the storm starts; afterwards the gateway
    # pauses for Retry-After (1 s) after a 429 and halves its concurrency to 1
    bound = 3 + 2 * storm_s
    res.check("429s bounded by the pause (<= 3 + 2/s)", len(refused) <= bound, f"{len(refused)} in {storm_s:.0f}s")
    res.check(
        "concurrency shrank to 1 and the deployment paused for Retry-After",
        low["limit"] == 1 and low["shrinks"] >= 1 and low["paused"] >= 1,
        low,
    )
    eps = rows(out, "episodes")
    errors = [r for r in eps if r["end_reason"] == "llm_error"]
    if retries is not None:
        res.check(
            "with enough retries every call outlived the storm",
            not errors and summary.exit_code() == 0,
            f"{len(errors)} llm_error",
        )
    else:
        res.check(
            "with the default retries calls gave up as rate_limit",
            errors and all("rate_limit" in (r["error"] or "") for r in errors),
            [r["error"] for r in errors][:2],
        )
    _units_done(res, out)
    res.notes.append(
        f"{name}: {len(refused)} x 429 in {storm_s:.0f}s, retries {retries if retries is not None else 'default 5'}: "
        f"{len(errors)}/{len(eps)} episodes ended llm_error"
    )
    res.end_run()


def rate_limit_storm(lab: Lab, storm_s: float = 30.0) -> ScenarioResult:
    """Every request answered 429 for ``storm_s`` seconds: once with retries to outlast it, once
    with the default retries (calls give up as ``rate_limit``, bounded)."""
    res = ScenarioResult(f"429 storm ({storm_s:.0f}s)")
    lab.ray_address()
    _storm_run(lab, res, "storm", storm_s, retries=int(2 * storm_s) + 10, workers=3)
    # one worker: its call gets an attempt about every second, so 6 attempts end inside 12 s
    _storm_run(lab, res, "storm-default-retries", min(storm_s, 12.0), retries=None, workers=1)
    return res
