"""Benchmark: time `recap report` over a synthetic run with about 1,000,000 message rows.

    .venv/bin/python bench/reports.py [--messages 1000000] [--repeat 3] [--run-dir DIR]

Writes the run (reports.synthetic) into a temporary folder unless --run-dir names an existing
one, then times the whole report (open the run, every SQL query, the viewer, and writing
Markdown, HTML, LaTeX and CSV) --repeat times and prints the best and median, with a per-query
breakdown of one extra pass and the load average (the machine is shared; a loaded machine gives
slower figures). Target: <= 5 s for 1,000,000 messages.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from reports.build import FORMATS, ReportOptions, build_report, write_report  # noqa: E402
from reports.synthetic import SyntheticSpec, write_synthetic_run  # noqa: E402
from reports.views import materialize, named_query, open_runs_checked, sql_names  # noqa: E402


def _breakdown(run_dir: Path) -> list[tuple[str, float]]:
    out = []
    t = time.perf_counter()
    con, _ = open_runs_checked([run_dir])
    out.append(("open run (views)", time.perf_counter() - t))
    t = time.perf_counter()
    materialize(con, ("attempts", "episode_modes"))
    out.append(("materialize attempts, episode_modes", time.perf_counter() - t))
    for name in sql_names():
        if name in ("macros", "views") or name.startswith("viewer"):
            continue
        t = time.perf_counter()
        named_query(con, name)
        out.append((name, time.perf_counter() - t))
    t = time.perf_counter()
    ids = named_query(con, "viewer_sample", {"n": 8}).column("episode_id")
    for name in ("viewer_episodes", "viewer_nodes", "viewer_steps", "viewer_calls", "viewer_messages"):
        named_query(con, name, {"ids": ids})
    out.append(("viewer (8 episodes)", time.perf_counter() - t))
    con.close()
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--messages", type=int, default=1_000_000)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--run-dir", help="use (or create) this run folder instead of a temporary one")
    a = p.parse_args()

    with tempfile.TemporaryDirectory(prefix="recap-report-bench-") as tmp:
        run_dir = Path(a.run_dir) if a.run_dir else Path(tmp) / "run"
        if not (run_dir / "messages").is_dir():
            t = time.perf_counter()
            counts = write_synthetic_run(run_dir, SyntheticSpec(messages=a.messages))
            print(
                f"generated synthetic run in {time.perf_counter() - t:.1f} s: "
                + ", ".join(f"{k} {v:,}" for k, v in counts.items())
            )
        size = sum(f.stat().st_size for f in run_dir.rglob("*.parquet"))
        print(f"run folder: {run_dir} ({size / 2**20:.0f} MiB of Parquet)")
        out_dir = Path(tmp) / "report"
        times = []
        for i in range(a.repeat):
            t = time.perf_counter()
            report = build_report([run_dir], ReportOptions(formats=FORMATS))
            written = write_report(report, out_dir, FORMATS)
            times.append(time.perf_counter() - t)
            print(f"  report run {i + 1}: {times[-1]:.2f} s ({len(written)} files)")
        html = (out_dir / "report.html").stat().st_size
        print(
            f"recap report (md, html, tex, csv): best {min(times):.2f} s, median {statistics.median(times):.2f} s "
            f"over {a.repeat} runs; report.html {html / 2**20:.2f} MiB; load average {os.getloadavg()[0]:.1f} "
            f"on {os.cpu_count()} CPUs; target <= 5 s"
        )
        print("breakdown of one more pass:")
        for name, secs in _breakdown(run_dir):
            print(f"  {name:40s} {secs:6.3f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
