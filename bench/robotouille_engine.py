"""Speed of our Robotouille engine next to the real engine's recorded build times.

Per instance: build time (make the environment and produce the first observation, median of
``--repeats`` runs), expert plan time and length (vs the optimal step count), and the median and
maximum time of one ``env.step`` while executing the expert plan. The real engine's
``create_time_s`` (recorded in each instance file, 2-core VM) is printed alongside; the summary
gives the overall ratio of total build times. Targets: every build <= 50 ms, median step <= 2 ms.

Usage: python bench/robotouille_engine.py [--data-dir DIR] [--selector asynchronous/9] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from workers.envs.robotouille import BENCHMARK  # noqa: E402
from workers.envs.robotouille.data import instance_path  # noqa: E402

BUILD_TARGET_MS = 50.0
STEP_TARGET_MS = 2.0


def _default_data_dir() -> str:
    return os.environ.get("ROBOTOUILLE_DATA") or str((REPO / ".." / "shared" / "data" / "robotouille").resolve())


def bench_instance(instance_id: str, data_dir: str, repeats: int) -> dict:
    builds = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        env = BENCHMARK.make(instance_id, data_dir=data_dir, step_multiplier=50)
        env.reset()
        builds.append(time.perf_counter() - t0)
    t0 = time.perf_counter()
    plan = env.expert_plan() or []
    plan_s = time.perf_counter() - t0
    steps = []
    success = False
    for action in plan:
        t0 = time.perf_counter()
        step = env.step(action)
        steps.append(time.perf_counter() - t0)
        success = step.success
    record = json.loads(instance_path(Path(data_dir), env.split, env.task, env.layout_seed).read_text())
    return {
        "id": instance_id,
        "real_create_s": float(record["create_time_s"]),
        "build_s": statistics.median(builds),
        "plan_s": plan_s,
        "plan_len": len(plan),
        "optimal": env.optimal_steps,
        "success": success,
        "step_median_s": statistics.median(steps) if steps else 0.0,
        "step_max_s": max(steps) if steps else 0.0,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data-dir", default=_default_data_dir())
    parser.add_argument("--selector", default=None)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)

    ids = BENCHMARK.list_instances(args.selector)
    BENCHMARK.make(ids[0], data_dir=args.data_dir)  # parse the domain once (shared, cached)
    rows = [bench_instance(i, args.data_dir, args.repeats) for i in ids]

    header = f"{'instance':<70} {'real build':>10} {'our build':>9} {'speedup':>8} {'plan':>9} {'ratio':>5} {'plan ms':>7} {'step med':>8} {'step max':>8}"
    print(header)
    print("-" * len(header))
    for r in rows:
        short = r["id"].removeprefix("robotouille/")
        if len(short) > 70:
            short = short[:67] + "..."
        print(
            f"{short:<70} {r['real_create_s'] * 1000:>8.0f}ms {r['build_s'] * 1000:>7.1f}ms "
            f"{r['real_create_s'] / r['build_s']:>7.0f}x {r['plan_len']:>4}/{r['optimal']:<4} "
            f"{r['plan_len'] / r['optimal']:>5.2f} {r['plan_s'] * 1000:>7.1f} "
            f"{r['step_median_s'] * 1000:>6.3f}ms {r['step_max_s'] * 1000:>6.3f}ms"
        )
    builds = [r["build_s"] for r in rows]
    step_meds = [r["step_median_s"] for r in rows]
    ratios = [r["plan_len"] / r["optimal"] for r in rows]
    real_total = sum(r["real_create_s"] for r in rows)
    ours_total = sum(builds)
    print()
    print(f"instances: {len(rows)}   expert solved: {sum(r['success'] for r in rows)}/{len(rows)}")
    print(
        f"build: median {statistics.median(builds) * 1000:.1f} ms, max {max(builds) * 1000:.1f} ms "
        f"(target <= {BUILD_TARGET_MS:.0f} ms: {'met' if max(builds) * 1000 <= BUILD_TARGET_MS else 'MISSED'})"
    )
    print(
        f"step: median of medians {statistics.median(step_meds) * 1000:.3f} ms, worst median "
        f"{max(step_meds) * 1000:.3f} ms, worst single {max(r['step_max_s'] for r in rows) * 1000:.3f} ms "
        f"(target median <= {STEP_TARGET_MS:.0f} ms: {'met' if max(step_meds) * 1000 <= STEP_TARGET_MS else 'MISSED'})"
    )
    print(
        f"total build: real engine {real_total:.1f} s vs ours {ours_total:.3f} s -> {real_total / ours_total:.0f}x faster overall"
    )
    print(
        f"expert plan/optimal: mean {statistics.mean(ratios):.3f}, max {max(ratios):.3f}; "
        f"plan time median {statistics.median(r['plan_s'] for r in rows) * 1000:.1f} ms, "
        f"max {max(r['plan_s'] for r in rows) * 1000:.1f} ms"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
