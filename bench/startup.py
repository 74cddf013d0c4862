"""What a user waits for before anything runs: a refused sweep, and the start of a run's actors.

Part 1: ``recap run`` and ``recap estimate`` on sweeps that are refused (an unknown provider prefix,
``max_tokens`` above the model's limit, a bad quota window), each in a fresh process as a user runs
it; CPU seconds of the process (user + system) and what it imported (litellm, ray, duckdb). A refusal
reads litellm's installed files (pipeline/litellm_files.py) instead of importing litellm.

Part 2: N actors started on a local cluster started here (pipeline.raysetup.init_ray), once without a
``runtime_env`` (how a run's actors start there: ``actor_runtime_env()`` is None) and once with the
job's full ``runtime_env`` (how they start on a joined cluster: through Ray's setup_worker.py), timed
from the first ``.remote()`` to every actor's first answer, in turns.

    .venv/bin/python bench/startup.py [--actors 6] [--rounds 2]

Figures only, nothing asserted.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")

BASE = """run: refused
output: {out}
models:
{model}methods: [{{method: react}}]
environments: [{{benchmark: blocksworld, tasks: ["3"]}}]
"""
CASES = {
    "unknown provider prefix": "  - model: nosuchprovider/zzz\n    api_base: http://127.0.0.1:9/v1\n",
    "max_tokens beyond the model": "  - model: openai/gpt-4o-mini\n    api_key_env: RECAP_BENCH_KEY\n    params: {max_tokens: 16385}\n",
    "meaningless quota window": "  - model: offline/expert\n    rpm: 10\n    window_s: 0\n",
}
PROBE = "import sys, runpy; sys.argv = ['recap'] + sys.argv[1:]\ntry:\n    runpy.run_module('pipeline.cli', run_name='__main__')\nfinally:\n    print('LOADED', *[m for m in ('litellm', 'ray', 'duckdb') if m in sys.modules], file=sys.stderr)\n"


def refusal(command: str, text: str, tmp: Path) -> tuple[int, float, str, str]:
    """(exit status, CPU seconds, the error line, heavy modules loaded) of one refused command."""
    path = tmp / "sweep.yaml"
    path.write_text(text)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    env = {**os.environ, "RECAP_BENCH_KEY": "not-a-secret", "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", PROBE, command, str(path)], capture_output=True, text=True, env=env, cwd=tmp)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    lines = done.stderr.strip().splitlines()
    loaded = next((ln.split()[1:] for ln in lines if ln.startswith("LOADED")), [])
    error = next((ln for ln in lines if ln.startswith("recap: error")), lines[0] if lines else "")
    return done.returncode, cpu, error, ",".join(loaded) or "-"


def actor_starts(n: int, runtime_env: dict | None) -> float:
    import ray

    @ray.remote(num_cpus=0)
    class Probe:
        def ping(self) -> int:
            return os.getpid()

    t = time.monotonic()
    actors = [Probe.options(runtime_env=runtime_env).remote() for _ in range(n)]
    ray.get([a.ping.remote() for a in actors], timeout=600)
    took = time.monotonic() - t
    for a in actors:
        ray.kill(a)
    return took


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--actors", type=int, default=6, help="actors started per measurement")
    ap.add_argument("--rounds", type=int, default=2, help="measurements of each kind, in turns")
    args = ap.parse_args()

    print(f"{'refused case':<30} {'command':<9} {'exit':>4} {'CPU s':>6}  loaded  error")
    with tempfile.TemporaryDirectory(prefix="recap-startup-") as tmp:
        for name, model in CASES.items():
            text = BASE.format(out=Path(tmp) / "out", model=model)
            for command in ("run", "estimate"):
                rc, cpu, error, loaded = refusal(command, text, Path(tmp))
                print(f"{name:<30} {command:<9} {rc:>4} {cpu:6.2f}  {loaded:<6}  {error[:90]}")

    import ray

    from bench.pipeline import start_ray
    from pipeline.raysetup import actor_runtime_env, runtime_env, shutdown_ray

    start_ray(None)
    assert actor_runtime_env() is None
    without, with_env = [], []
    for _ in range(args.rounds):
        without.append(actor_starts(args.actors, None))
        with_env.append(actor_starts(args.actors, runtime_env()))
    shutdown_ray()
    del ray
    mean = lambda xs: sum(xs) / len(xs)  # noqa: E731
    print(
        f"{args.actors} actors started: {mean(without):.1f} s without a runtime_env (each round: "
        f"{', '.join(f'{x:.1f}' for x in without)}), {mean(with_env):.1f} s with the job's runtime_env "
        f"({', '.join(f'{x:.1f}' for x in with_env)}): ratio {mean(with_env) / mean(without):.2f}"
    )


if __name__ == "__main__":
    main()
