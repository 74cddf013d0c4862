"""Chaos, security and bad-input figures: what a crash, a provider fault or a typo costs.

Every scenario plays one kind of failure against the real pipeline (driver, episode workers,
LLM gateway, sink, run folder) with the offline test doubles and the loopback fake OpenAI
server - nothing leaves the machine - and reports, over its randomised runs:

    lost        units without a completed terminal row / finished episodes whose rows vanished
    duplicated  terminal rows beyond one per unit
    overspend   $ past a cap as the provider billed it, or paid again for a completed unit

The scenarios (``--only NAME``; the functions live in ``tests/pipeline/chaos/MODULE.py``):

    worker    kills     episode workers SIGKILLed at random points of 20 episodes
    gateway   kills     the gateway and budget actors SIGKILLed under a binding run cap
    driver    kills     ``recap run`` / ``recap resume`` SIGKILLed, then resumed to the end
    sigint    signals   Ctrl-C once during ``recap run``: episodes in flight finish, exit 130, resume
    sigint2   signals   Ctrl-C twice: episodes in flight cut, every paid call kept, exit 130, resume
    orphans   signals   ``recap run`` on its own local Ray SIGKILLed: its watcher stops the cluster;
                        driver + watcher SIGKILLed: processes left, the next ``recap resume`` stops
                        them (says so) and finishes; orphans left, calls re-paid vs in flight
    sink      kills     the sink actor SIGKILLed mid-run (Ray restarts it), then ``recap resume``
    sinkgone  kills     the sink SIGKILLed with no restart left: the driver stops; ``recap resume``
    faults    faults    transient provider faults and context-length errors
    storm     faults    a 429 storm of --storm-s seconds
    parts     folders   corrupt part files: reported, resume re-runs only the lost units
    inputs    inputs    bad sweep files and flags: one line, nothing written, no model call
    secrets   exposure  no key in files, logs or output; every socket on loopback
    sql       guards    every write / escape attack through ``recap sql``: exit 2, 0 bytes changed
    sqlres    guards    memory and time attacks through ``recap sql``: stopped at the limit, peak RSS under it
    caps      guards    a lying provider (usage, n choices, cost figure) against a small run cap
    unreadable guards   HTTP 200s nobody can read against a small run cap, over a run and 2 resumes
    lock      guards    synchronised threads and processes racing for the driver lock: 1 winner
    userfiles user_files  files a user hands us (--from, instances file, patches, selectors): one line, exit 2
    wiki      wiki      FEVER's Wikipedia: dripping, huge and gzip-bomb pages, off-origin redirects, tampered snapshots
    sandbox_local sandbox_local  escapes, disk overruns, symlinks and a 19 MB view against a local sandbox
    hostilecalls hostile_calls  a provider's hostile tool calls (200,000-deep, 5 MB, repeated ids, ...): the model's, recorded, charged, capped
    sandbox_docker sandbox_docker  a model's tool calls against a docker sandbox: symlink escapes, hostile paths, a 19 MB view, disk past each bound

    python -m tests.pipeline.chaos.lab                          # every scenario (about 6 minutes on 2 cores)
    python -m tests.pipeline.chaos.lab --only worker gateway    # some of them
    python -m tests.pipeline.chaos.lab --runs 3 --seed 7        # more randomised runs of the kill scenarios
    python -m tests.pipeline.chaos.lab --storm-s 30 --keep      # the 429 storm's length; keep the run folders

The kill, signal, fault, folder and exposure scenarios are asserted by ``tests/pipeline/chaos/test_chaos_slow.py``
and ``tests/pipeline/chaos/test_chaos_sink.py`` (``pytest -m slow tests/pipeline/chaos``); the guards borrow the
attacks and helpers of ``tests/reports/test_sql_read_only.py``, ``tests/workers/gateway/test_hostile_provider.py``
and ``tests/pipeline/test_driver_lock.py``, which assert them one by one. Prints a table; exit
status 1 when a scenario failed a check.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")

#: name -> (module, function, takes runs[, fixed keyword arguments])
SCENARIOS: dict[str, tuple] = {
    "worker": ("kills", "worker_kill", True),
    "gateway": ("kills", "gateway_kill", True),
    "driver": ("kills", "driver_kill", True),
    "sigint": ("signals", "sigint", False, {"presses": 1}),
    "sigint2": ("signals", "sigint", False, {"presses": 2}),
    "orphans": ("signals", "orphans", False),
    "sink": ("kills", "sink_kill", True, {"restarts": True}),
    "sinkgone": ("kills", "sink_kill", True, {"restarts": False}),
    "faults": ("faults", "provider_faults", False),
    "storm": ("faults", "rate_limit_storm", False),
    "parts": ("folders", "corrupt_parts", False),
    "inputs": ("inputs", "bad_inputs", False),
    "secrets": ("exposure", "secrets_and_sockets", False),
    "sql": ("guards", "sql_attacks", False),
    "sqlres": ("guards", "sql_resource_attacks", False),
    "caps": ("guards", "cap_attacks", False),
    "unreadable": ("guards", "unreadable_attacks", False),
    "lock": ("guards", "lock_race", False),
    "userfiles": ("user_files", "userfiles", False),
    "wiki": ("wiki", "wiki", False),
    "sandbox_local": ("sandbox_local", "sandbox_local", False),
    "hostilecalls": ("hostile_calls", "hostile_calls", False),
    "sandbox_docker": ("sandbox_docker", "sandbox_docker", False),
}


def _fmt_usd(v: float | None) -> str:
    return "-" if v is None else f"${v:.6f}"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--only", nargs="+", choices=sorted(SCENARIOS), help="run only these scenarios")
    p.add_argument("--runs", type=int, default=None, help="randomised runs of each kill scenario (default: 1, driver: 2)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--storm-s", type=float, default=30.0, help="length of the 429 storm in seconds")
    p.add_argument("--keep", action="store_true", help="keep the run folders (printed at the end)")
    p.add_argument("--verbose", action="store_true", help="print every check, not only failed ones")
    args = p.parse_args(argv)

    import importlib

    from tests.pipeline.chaos.harness import Lab, ScenarioResult

    root = Path(tempfile.mkdtemp(prefix="chaos-", dir=os.environ.get("TMPDIR", "/tmp")))
    lab = Lab(root, seed=args.seed, log=lambda m: print(m, flush=True))
    results = []
    t_all = time.monotonic()
    try:
        for name in args.only or list(SCENARIOS):
            module, fn, takes_runs, *fixed = SCENARIOS[name]
            run = getattr(importlib.import_module(f"tests.pipeline.chaos.{module}"), fn)
            kwargs = dict(fixed[0]) if fixed else {}
            if takes_runs and args.runs is not None:
                kwargs["runs"] = args.runs
            if name == "storm":
                kwargs["storm_s"] = args.storm_s
            print(f"-- {name} ...", flush=True)
            t0 = time.monotonic()
            try:
                res = run(lab, **kwargs)
            except Exception as exc:  # a scenario that crashes is a failed scenario, not a crashed bench
                res = ScenarioResult(name, runs=1)
                res.check("scenario ran to the end", False, f"{type(exc).__name__}: {exc}"[:500])
            res.wall_s = time.monotonic() - t0
            results.append(res)
            for c in res.checks if args.verbose else res.failures:
                print(f"   {c}", flush=True)
            print(f"   {res.passed}/{res.runs} runs passed in {res.wall_s:.0f}s", flush=True)
    finally:
        lab.close()
        if not args.keep:
            shutil.rmtree(root, ignore_errors=True)

    from rich.console import Console
    from rich.table import Table

    t = Table(title=f"recap-eval chaos suite (seed {args.seed}, {time.monotonic() - t_all:.0f}s)")
    for col, just in (
        ("scenario", "left"),
        ("runs", "right"),
        ("passed", "right"),
        ("lost", "right"),
        ("duplicated", "right"),
        ("overspend", "right"),
        ("checks", "right"),
        ("s", "right"),
        ("figures", "left"),
    ):
        t.add_column(col, justify=just)
    for r in results:
        t.add_row(
            r.name,
            str(r.runs),
            str(r.passed),
            str(r.lost),
            str(r.duplicated),
            _fmt_usd(r.overspend_usd),
            f"{len(r.checks) - len(r.failures)}/{len(r.checks)}",
            f"{r.wall_s:.0f}",
            "; ".join(r.notes),
        )
    Console(width=None if sys.stdout.isatty() else 240, highlight=False).print(t)
    if args.keep:
        print(f"run folders kept under {root}")
    return 0 if all(r.ok for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
