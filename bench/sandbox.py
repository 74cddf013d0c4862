"""Sandbox figures: start, a command round trip (``true``) and teardown, p50/p95, for both kinds;
and how many idle docker sandboxes one node holds.

    .venv/bin/python bench/sandbox.py            # 20 runs per kind (about a minute)
    .venv/bin/python bench/sandbox.py --runs 50 --kinds docker

Start is ``open_sandbox`` (clone at the base commit, container start, copy in, git set-up);
round trip is ``run("true")`` on a warm sandbox; teardown is ``close``. Density: the memory an
idle container uses (its cgroup's usage less page cache, from ``docker stats``) against the
node's available memory, and the worst case the memory limit allows (MemTotal / memory_bytes).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from workers.sandbox import LABEL_RUN, SandboxSpec, open_sandbox, remove_labelled  # noqa: E402


def _pct(xs: list[float], q: float) -> float:
    xs = sorted(xs)
    return xs[min(len(xs) - 1, round(q * (len(xs) - 1)))]


def _repo(root: Path) -> tuple[str, str]:
    p = root / "repo"
    p.mkdir()
    for i in range(50):
        (p / f"m{i}.py").write_text(f"def f{i}():\n    return {i}\n" * 20)
    g = ["git", "-c", "user.name=b", "-c", "user.email=b@b"]
    subprocess.run([*g, "init", "-q"], cwd=p, check=True)
    subprocess.run([*g, "add", "."], cwd=p, check=True)
    subprocess.run([*g, "commit", "-qm", "x"], cwd=p, check=True)
    return str(p), subprocess.run(["git", "rev-parse", "HEAD"], cwd=p, capture_output=True, text=True).stdout.strip()


def _meminfo() -> dict[str, int]:
    out = {}
    for line in Path("/proc/meminfo").read_text().splitlines():
        k, v = line.split(":", 1)
        out[k] = int(v.split()[0]) * 1024
    return out


def bench_kind(kind: str, spec: SandboxSpec, runs: int) -> None:
    start, rtt, down = [], [], []
    for _ in range(runs):
        t = time.perf_counter()
        sb = open_sandbox(kind, spec)
        start.append(time.perf_counter() - t)
        for _ in range(5):
            t = time.perf_counter()
            sb.run("true")
            rtt.append(time.perf_counter() - t)
        t = time.perf_counter()
        sb.close()
        down.append(time.perf_counter() - t)
    for name, xs in (("start", start), ("round trip (true)", rtt), ("teardown", down)):
        print(
            f"{kind:6} {name:18} p50 {1000 * statistics.median(xs):7.1f} ms   p95 {1000 * _pct(xs, 0.95):7.1f} ms   (n={len(xs)})"
        )


def _shim_rss() -> float:
    """Median resident memory of the host's containerd-shim processes (one per container)."""
    rss = []
    for d in Path("/proc").glob("[0-9]*"):
        try:
            if not (d / "comm").read_text().startswith("containerd-shim"):
                continue
            for line in (d / "status").read_text().splitlines():
                if line.startswith("VmRSS:"):
                    rss.append(int(line.split()[1]) * 1024)
        except OSError:
            continue
    return statistics.median(rss) if rss else 0.0


def density(spec: SandboxSpec, n: int) -> None:
    import docker

    boxes = [open_sandbox("docker", spec) for _ in range(n)]
    try:
        time.sleep(2)
        shim = _shim_rss()
        client = docker.from_env()
        used = []
        for sb in boxes:
            st = client.containers.get(sb.container_id).stats(stream=False)["memory_stats"]  # type: ignore[attr-defined]
            cache = st.get("stats", {}).get("cache", st.get("stats", {}).get("inactive_file", 0))
            used.append(st["usage"] - cache)
    finally:
        for sb in boxes:
            sb.close()
    mem = _meminfo()
    inside = statistics.median(used)
    per = inside + shim
    print(
        f"idle docker sandbox memory: p50 {inside / 1e6:.1f} MB in its cgroup (usage less page cache) "
        f"+ {shim / 1e6:.1f} MB host-side containerd-shim RSS = {per / 1e6:.1f} MB ({n} containers)"
    )
    print(
        f"node: {mem['MemTotal'] / 1e9:.1f} GB total, {mem['MemAvailable'] / 1e9:.1f} GB available -> "
        f"~{int(mem['MemAvailable'] // per)} idle sandboxes by memory; "
        f"{int(mem['MemTotal'] // spec.limits.memory_bytes)} if each used its full {spec.limits.memory_bytes >> 20} MiB limit"
    )


def main() -> int:
    """Print the figures."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--kinds", default="docker,local")
    ap.add_argument("--density", type=int, default=10, help="idle containers opened at once for the memory figure (0: skip)")
    args = ap.parse_args()
    labels = {LABEL_RUN: f"bench-{uuid.uuid4().hex[:8]}"}
    with tempfile.TemporaryDirectory() as tmp:
        path, commit = _repo(Path(tmp))
        spec = SandboxSpec(path, commit, labels=labels)
        try:
            for kind in args.kinds.split(","):
                bench_kind(kind, spec, args.runs)
            if "docker" in args.kinds and args.density:
                density(spec, args.density)
        finally:
            remove_labelled(labels)
    return 0


if __name__ == "__main__":
    sys.exit(main())
