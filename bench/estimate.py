"""How long ``recap estimate`` takes on every sweep file of ``examples/paper/`` (issue 36 item 6: at
most 10 s each; the ALFWorld one took 7.5 minutes of CPU when it built all 134 games).

Each file is estimated in a fresh process, as a user runs it (imports included). Printed per file:
exit status, wall-clock and CPU seconds (user + system of the process) and the estimate's total
line, or its error. CPU seconds are the figure to compare on a shared machine: wall-clock time
grows with the load. ``swe-verified.yaml`` needs the 500 records: when ``recap data`` finds none,
this script stores 500 synthetic ones in the dataset's schema (bench/swe_preflight.py's) in a
temporary folder, so the estimate runs with the Docker daemon and images as they are here.

    .venv/bin/python bench/estimate.py [FILE ...]     # default: examples/paper/*.yaml
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.swe_preflight import _records  # noqa: E402

N_VERIFIED = 500


def _verified_data(tmp: Path) -> dict[str, str]:
    """Environment variables giving swe-verified its records: the ones found here, else 500 synthetic."""
    env = dict(os.environ)
    probe = subprocess.run(
        [sys.executable, "-c", "from workers.envs.swe_verified.dataset import records; records()"],
        cwd=ROOT,
        capture_output=True,
    )
    if probe.returncode == 0:
        return env
    src = tmp / "verified.jsonl"
    src.write_text("".join(json.dumps(r) + "\n" for r in _records(N_VERIFIED)))
    data = tmp / "swebench-verified"
    fetch = [sys.executable, "-m", "pipeline.cli", "data", "fetch", "swebench-verified", "--from", str(src), "--dest", str(data)]
    subprocess.run(fetch, cwd=ROOT, check=True, capture_output=True)
    env["SWEBENCH_VERIFIED_DATA"] = str(data)
    return env


def timed(path: Path, env: dict[str, str]) -> tuple[int, float, float, str]:
    """(exit status, wall s, CPU s, last line) of ``recap estimate PATH`` in a fresh process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "pipeline.cli", "estimate", str(path)], cwd=ROOT, env=env, capture_output=True, text=True
    )
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    lines = [x for x in proc.stdout.splitlines() if x.startswith("total:")] or proc.stderr.strip().splitlines() or [""]
    return proc.returncode, wall, cpu, lines[-1]


def main(argv: list[str]) -> None:
    files = [Path(a) for a in argv] or sorted((ROOT / "examples" / "paper").glob("*.yaml"))
    os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    with tempfile.TemporaryDirectory() as tmp:
        env = _verified_data(Path(tmp))
        print(f"{'file':<24} {'rc':>3} {'wall s':>7} {'cpu s':>7}  result")
        for f in files:
            rc, wall, cpu, line = timed(f, env)
            print(f"{f.name:<24} {rc:>3} {wall:>7.1f} {cpu:>7.1f}  {line[:110]}", flush=True)
    print(f"(load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)")


if __name__ == "__main__":
    main(sys.argv[1:])
