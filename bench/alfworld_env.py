"""Cost of one ALFWorld environment instance: make, reset and step time, resident memory.

Part 1 plays the expert walkthrough of the first N games of each task type (default 1 per type)
and keeps every instance alive until the end, so the RSS growth divided by the instance count is
what a worker pays per *open* game. Part 2 opens, plays and closes M further games one after the
other (default 12), the way an episode worker uses them, and prints the RSS growth per game
(closed games hand their planner library to the next one, so it should stay near zero). "again s"
is a second reset of the same game after its walkthrough: its PDDL translation is cached per process
(workers/envs/alfworld/translations.py), so only the first reset of a game pays for it.
Run from the repository root:

    .venv/bin/python bench/alfworld_env.py [--per-type N] [--sequential M] [--version 2.1.1|2.1.2] [--no-translation-cache]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from workers.envs.alfworld import AlfworldBenchmark  # noqa: E402
from workers.envs.alfworld.task_types import TASK_TYPES  # noqa: E402
from workers.envs.alfworld.translations import TRANSLATIONS  # noqa: E402

DEFAULT_DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "alfworld"


def rss_mib() -> float:
    """Current resident set size of this process (Linux /proc)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    raise RuntimeError("VmRSS not found in /proc/self/status")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--per-type", type=int, default=1, help="games per task type")
    parser.add_argument("--version", default="2.1.1", choices=["2.1.1", "2.1.2"])
    parser.add_argument("--sequential", type=int, default=12, help="games opened and closed in turn")
    parser.add_argument(
        "--no-translation-cache",
        action="store_true",
        help="translate on every reset, as textworld alone does (the before figure)",
    )
    parser.add_argument("--data", default=os.environ.get("ALFWORLD_DATA", str(DEFAULT_DATA)))
    args = parser.parse_args()

    if args.no_translation_cache:
        TRANSLATIONS.size = 0  # every translation evicted at once: each one runs
    bench = AlfworldBenchmark(Path(args.data).resolve())
    ids = [i for short in TASK_TYPES for i in bench.list_instances(short)[: args.per_type]]

    t0 = time.perf_counter()
    import alfworld.agents.environment.alfred_tw_env  # noqa: F401  (the engine import, timed once)
    import textworld.gym  # noqa: F401

    print(f"engine import: {time.perf_counter() - t0:.2f} s")
    base = rss_mib()
    print(f"RSS after import: {base:.0f} MiB; {len(ids)} games, version {args.version}")
    print(f"{'game':<58} {'make s':>7} {'reset s':>8} {'step ms':>8} {'steps':>5} {'won':>4} {'again s':>8} {'RSS +MiB':>9}")

    envs, makes, resets, agains, steps = [], [], [], [], []
    for instance_id in ids:
        before = rss_mib()
        t = time.perf_counter()
        env = bench.make(instance_id, version=args.version)
        t_make = time.perf_counter() - t
        t = time.perf_counter()
        env.reset()
        t_reset = time.perf_counter() - t
        step_times, won = [], False
        for action in env.expert_plan() or []:
            t = time.perf_counter()
            won = env.step(action).success
            step_times.append(time.perf_counter() - t)
        t = time.perf_counter()
        env.reset()
        agains.append(time.perf_counter() - t)
        envs.append(env)
        makes.append(t_make)
        resets.append(t_reset)
        steps.extend(step_times)
        name = instance_id.split("/", 2)[2][:58]
        print(
            f"{name:<58} {t_make:7.3f} {t_reset:8.2f} {1000 * statistics.mean(step_times):8.1f} "
            f"{len(step_times):5d} {'yes' if won else 'no':>4} {agains[-1]:8.2f} {rss_mib() - before:9.1f}"
        )

    total = rss_mib() - base
    print(
        f"\nmean make {statistics.mean(makes):.3f} s | mean reset {statistics.mean(resets):.2f} s "
        f"(max {max(resets):.2f}) | mean step {1000 * statistics.mean(steps):.1f} ms "
        f"(max {1000 * max(steps):.1f}) over {len(steps)} steps"
    )
    print(
        f"first reset of a game {statistics.mean(resets):.2f} s, a later reset {statistics.mean(agains):.2f} s "
        f"(ratio {statistics.mean(resets) / statistics.mean(agains):.1f}); PDDL translations run: "
        f"{TRANSLATIONS.translations} for {len(ids)} games"
    )
    print(f"RSS delta with {len(envs)} live instances: {total:.0f} MiB = {total / len(envs):.1f} MiB per instance")
    for env in envs:
        env.close()
    print(f"RSS after closing all: {rss_mib() - base:+.0f} MiB vs after import")

    if args.sequential:
        every = bench.list_instances()
        chosen = every[:: max(1, len(every) // args.sequential)][: args.sequential]
        start, wins = rss_mib(), 0
        for instance_id in chosen:
            env = bench.make(instance_id, version=args.version)
            env.reset()
            for action in env.expert_plan() or []:
                wins += env.step(action).success
            env.close()
        grown = rss_mib() - start
        print(
            f"sequential open/play/close of {len(chosen)} games ({wins} won): RSS {grown:+.0f} MiB "
            f"= {grown / len(chosen):+.1f} MiB per game"
        )


if __name__ == "__main__":
    main()
