"""Benchmark: `recap view` response times on a run of 10,000 episodes / 1,000,000 messages.

    .venv/bin/python bench/view.py [--messages 1000000] [--episodes 10000] [--repeat 5] [--run-dir DIR]

Writes a synthetic run with the real schemas (reports.synthetic: episodes, calls, messages,
steps, tree nodes consistent with each other) into a temporary folder unless --run-dir names an
existing one, starts the viewer on a free loopback port and times whole HTTP requests (query +
HTML + transfer) with --repeat runs each: the episode list (first page, a deep page, sorted),
every filter with one of its values, full-text searches over the messages, episode pages, a
call's window and the comparison of two arms. Prints median and worst per request and the
worst per group against the targets: list and filters <= 300 ms, an episode page <= 500 ms.
The machine is shared: the load average is printed with the figures.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
import urllib.error
import urllib.request
from pathlib import Path
from urllib.parse import urlencode

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import pyarrow as pa  # noqa: E402
import pyarrow.compute as pc  # noqa: E402
import pyarrow.parquet as pq  # noqa: E402

from reports.synthetic import SyntheticSpec, write_synthetic_run  # noqa: E402
from reports.webview.server import serve, stop  # noqa: E402

TARGET_MS = {"list": 300.0, "filter": 300.0, "search": 300.0, "episode": 500.0, "window": 500.0, "compare": 1000.0}


def _label_episodes(run_dir: Path) -> None:
    """The synthetic generator predates the episodes' ``label`` / ``profile`` columns: fill them
    like a sweep would (label = the method, profile paper) so the method filters have values."""
    for f in sorted((run_dir / "episodes").glob("part-*.parquet")):
        t = pq.read_table(f)
        changed = False
        for col, value in (("label", None), ("profile", "paper")):
            if col in t.column_names and t[col].null_count == t.num_rows:
                fill = t["method"] if value is None else pa.array([value] * t.num_rows, pa.string())
                t = t.set_column(t.column_names.index(col), col, pc.cast(fill, t.schema.field(col).type))
                changed = True
        if changed:
            tmp = f.with_name(f".tmp-{f.name}")
            pq.write_table(t, tmp)
            os.replace(tmp, f)


def _get(url: str) -> tuple[int, float, int]:
    t = time.perf_counter()
    try:
        with urllib.request.urlopen(url, timeout=60) as r:
            body = r.read()
            code = r.status
    except urllib.error.HTTPError as exc:
        body, code = exc.read(), exc.code
    return code, (time.perf_counter() - t) * 1000, len(body)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--messages", type=int, default=1_000_000)
    p.add_argument("--episodes", type=int, default=10_000)
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--run-dir", help="use (or create) this run folder instead of a temporary one")
    a = p.parse_args()

    with tempfile.TemporaryDirectory(prefix="recap-view-bench-") as tmp:
        run_dir = Path(a.run_dir) if a.run_dir else Path(tmp) / "run"
        if not (run_dir / "messages").is_dir():
            t = time.perf_counter()
            mean_calls = max(2, (a.messages // a.episodes - 2) // 2)  # messages per episode = 2 x calls + 2
            counts = write_synthetic_run(run_dir, SyntheticSpec(messages=a.messages, mean_calls=mean_calls))
            _label_episodes(run_dir)
            print(
                f"generated synthetic run in {time.perf_counter() - t:.1f} s: "
                + ", ".join(f"{k} {v:,}" for k, v in counts.items())
            )
        size = sum(f.stat().st_size for f in run_dir.rglob("*.parquet"))
        print(f"run folder: {run_dir} ({size / 2**20:.0f} MiB of Parquet)")

        t = time.perf_counter()
        server, thread = serve([run_dir], 0, poll_s=0)
        print(f"viewer start (scan, views, episode list, search text of every message): {time.perf_counter() - t:.2f} s")
        try:
            snap = server.catalog.snap
            base = server.url
            eps = snap.query("SELECT run_id, episode_id, llm_calls FROM _episode_list ORDER BY episode_id").rows
            pick = [eps[i] for i in range(0, len(eps), max(1, len(eps) // 5))][:5]
            words = snap.query("SELECT content FROM messages WHERE seq = 5 LIMIT 1").rows[0][0].split()
            requests: list[tuple[str, str, str]] = [
                ("list", "first page", "episodes"),
                ("list", "page 100, 50 per page", "episodes?page=100"),
                ("list", "sorted by cost, descending", "episodes?sort=cost_usd&dir=desc"),
                ("list", "200 per page", "episodes?per=200"),
            ]
            for param, values in snap.options.items():
                if values:
                    v = values[len(values) // 2]
                    v = str(v).lower() if isinstance(v, bool) else str(v)
                    requests.append(("filter", f"{param} = {v}", "episodes?" + urlencode({param: v})))
            arms = snap.options.get("arm") or []
            if len(arms) >= 2:
                requests.append(
                    (
                        "filter",
                        "arm + success + sort",
                        "episodes?" + urlencode({"arm": arms[0], "success": "false", "sort": "steps"}),
                    )
                )
            for phrase in (words[0], " ".join(words[1:4]), words[2] + " [12345]", "no such text anywhere"):
                requests.append(("search", f"search {phrase!r}", "episodes?" + urlencode({"q": phrase})))
            for run_id, eid, calls in pick:
                requests.append(("episode", f"episode {eid} ({calls} calls)", "episode?" + urlencode({"run": run_id, "id": eid})))
                requests.append(
                    (
                        "window",
                        f"window of call {calls - 1} of {eid}",
                        "window?" + urlencode({"run": run_id, "id": eid, "call": calls - 1, "fragment": 1}),
                    )
                )
            if len(arms) >= 2:
                requests.append(
                    (
                        "compare",
                        f"compare arms {arms[0]} / {arms[1]}",
                        "compare?" + urlencode({"kind": "arm", "a": arms[0], "b": arms[1]}),
                    )
                )
            _get(base + "episodes")  # warm-up
            worst: dict[str, float] = {}
            print(f"{'request':58s} {'median ms':>10s} {'worst ms':>9s} {'KiB':>7s}")
            for group, label, path in requests:
                times, size = [], 0
                for _ in range(a.repeat):
                    code, ms, size = _get(base + path)
                    if code != 200:
                        raise SystemExit(f"{path}: HTTP {code}")
                    times.append(ms)
                worst[group] = max(worst.get(group, 0.0), max(times))
                print(f"{group + ': ' + label:58.58s} {statistics.median(times):10.1f} {max(times):9.1f} {size / 1024:7.0f}")
        finally:
            stop(server, thread)
        load = os.getloadavg()[0]
        print(f"worst per group over {a.repeat} runs each (load average {load:.1f} on {os.cpu_count()} CPUs):")
        ok = True
        for group, ms in worst.items():
            target = TARGET_MS[group]
            ok &= ms <= target
            print(f"  {group:8s} {ms:8.1f} ms  target <= {target:.0f} ms  {'ok' if ms <= target else 'OVER'}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
