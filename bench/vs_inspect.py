"""Side by side with Inspect AI: the same fake server, the same 10-call episodes, N in flight.

Each measurement runs one side alone in a fresh child process against a fresh fake OpenAI server
(``python -m workers.llm.offline.fake_server --latency-s 0.2``: ``FakeServer(FakeServerConfig(
latency_s=0.2))`` in a process of its own, so neither side's figures hold the server's CPU or memory):

- recap: ``bench/pipeline.py``'s ``run_one`` - the real driver, episode workers, gateway and sink
  in a local Ray cluster started by the child - with ReAct on blocksworld, ``limits: {llm_calls:
  10}`` and ``workers: N`` (``sweep_text`` raises the model's ``concurrency`` to N beyond 64);
  it writes the run's Parquet tables (episodes, messages, llm_calls, ...) and its manifests.
- inspect: Inspect AI's own ``eval()`` of a Task of N x rounds samples whose solver calls
  ``generate()`` 10 times (a 10-turn conversation: the sample's prompt, then one user observation
  after each reply), model ``openai/fake-gpt`` at the fake server through Inspect's OpenAI
  provider (chat completions), ``max_samples = max_connections = N``, no sandbox, no scorer,
  ``display="none"``; it writes its default log (one ``.eval`` file with every sample's messages
  and events) to a temporary folder. The prompt and observation sizes are set so a call carries
  about as many prompt tokens as recap's ReAct call does (the ``prompt tok`` column, counted by
  the server, shows both).

Figures, per side and N (each side's first N episodes are the warm-up; the window is from the
N-th episode's end to the last one's, as in ``bench/pipeline.py``):

- ep/min: episodes ended in the window / its span; % of ideal, ideal = N x 60 / (10 x 0.2 s);
- CPU ms/call: CPU seconds of the child's whole process tree (``bench.procstats``: for recap the
  driver and every Ray process, for Inspect its one process) spent in the window, per model
  call answered in it; sampled every 0.5 s and interpolated to the window's ends;
- peak PSS: the most the child's process tree held at once (sum over its processes, sampled
  every 0.5 s from this parent process, so the sampling costs neither side's CPU figure);
- written MB: what the side left on disk (recap: its run folder; Inspect: its log folder and its
  data and cache folders, pointed there; Ray's session logs under /tmp/ray are not counted).

Inspect AI runs from a virtual environment of its own: every Inspect release checked (0.3.160 to
0.3.285, the newest here) clashes with our litellm pins (0.3.259 and later need openai >= 3.1 at run time,
litellm 1.106 needs openai < 3; 0.3.258 and earlier cap fsspec at 2025.9.0, whose s3fs needs a
botocore older than litellm's boto3 >= 1.43.117), and only the Inspect child process needs it::

    python3.11 -m venv .venv-inspect && .venv-inspect/bin/pip install -r bench/requirements-inspect.txt
    .venv/bin/python bench/vs_inspect.py                            # 8 32 64 128 in flight, 3 rounds
    .venv/bin/python bench/vs_inspect.py --concurrency 8 32 --rounds 3 --only recap
    .venv/bin/python bench/vs_inspect.py --inspect-python /elsewhere/bin/python

Prints one table; figures only, nothing asserted. Linux only (reads /proc).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")

import bench.pipeline as pipeline_bench  # noqa: E402
from bench.pipeline import CALLS, LATENCY, start_server  # noqa: E402
from bench.procstats import ProcSample, snapshot  # noqa: E402

SIDES = ("recap", "inspect")
#: the interpreter of the Inspect side (``--inspect-python`` or RECAP_INSPECT_PYTHON override it)
INSPECT_PYTHON = ROOT / ".venv-inspect" / "bin" / "python"
SAMPLE_EVERY_S = 0.5
CHILD_TIMEOUT_S = 900
#: Inspect's first user message and each later observation, in characters: sized so a call
#: carries about the prompt tokens of recap's ReAct-on-blocksworld call (``prompt tok`` shows both)
INSPECT_PROMPT_CHARS = 4300
INSPECT_OBSERVATION_CHARS = 120
_FILLER = "You are in a room with a table and a stack of blocks; the red block is on the blue block. "


# ---------------------------------------------------------------- the child: one side, one N
def _text(chars: int, tag: str) -> str:
    return (tag + " " + _FILLER * (chars // len(_FILLER) + 1))[:chars]


def _written_bytes(folder: Path) -> int:
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())


class _NoArrivals:
    arrivals = 0


def child_recap(url: str, n: int, rounds: int, tmp: Path) -> dict[str, Any]:
    """``bench/pipeline.py``'s run of N workers x rounds episodes; the episodes' ends and calls."""
    import ray

    from pipeline.raysetup import init_ray
    from pipeline.spec import RaySpec
    from pipeline.store import RunStore

    os.environ["RECAP_BENCH_KEY"] = "bench-not-a-secret"
    for attempt in range(3):  # Ray gives its raylet 30 s to register: a busy machine may need another go
        try:
            init_ray(RaySpec())
            break
        except Exception:
            ray.shutdown()
            if attempt == 2:
                raise
    try:
        # run_one reads the in-process server's arrival count for its own CPU column; here the server
        # is another process and this script measures CPU itself (the child's process tree)
        pipeline_bench.run_one(_NoArrivals(), url, n, rounds, 0, 10.0, tmp)
    finally:
        ray.shutdown()
    (out,) = [p for p in tmp.iterdir() if p.is_dir()]
    eps, _ = RunStore(out).read_table("episodes", ["ended_at", "llm_calls", "end_reason"])
    ends = sorted(zip(eps.column("ended_at").to_pylist(), eps.column("llm_calls").to_pylist()))
    return {
        "ends": ends,
        "status": ",".join(sorted(set(eps.column("end_reason").to_pylist()))),
        "written": _written_bytes(tmp),
    }


def child_inspect(url: str, n: int, rounds: int, tmp: Path) -> dict[str, Any]:
    """Inspect's ``eval()`` of N x rounds samples, N at once, each ``generate()`` CALLS times."""
    from inspect_ai import Task
    from inspect_ai import eval as inspect_eval
    from inspect_ai.dataset import Sample
    from inspect_ai.model import ChatMessageUser
    from inspect_ai.solver import Generate, Solver, TaskState, solver

    ends: list[tuple[float, int]] = []

    @solver
    def conversation() -> Solver:
        async def solve(state: TaskState, generate: Generate) -> TaskState:
            for turn in range(CALLS):
                if turn:
                    state.messages.append(ChatMessageUser(content=_text(INSPECT_OBSERVATION_CHARS, f"Observation {turn}:")))
                state = await generate(state)
            ends.append((time.time(), sum(m.role == "assistant" for m in state.messages)))
            return state

        return solve

    os.environ["OPENAI_API_KEY"] = "bench-not-a-secret"
    samples = [Sample(input=_text(INSPECT_PROMPT_CHARS, f"Task {i}:"), id=i) for i in range(n * rounds)]
    logs = inspect_eval(
        Task(dataset=samples, solver=conversation(), name="vs-recap"),
        model="openai/fake-gpt",
        model_base_url=url,
        model_args={"responses_api": False},
        max_samples=n,
        max_connections=n,
        log_dir=str(tmp),
        display="none",
        log_level="warning",
        score=False,
    )
    log = logs[0]
    status = log.status if log.error is None else f"{log.status}: {str(log.error.message).splitlines()[0]}"
    return {"ends": sorted(ends), "status": status, "written": _written_bytes(tmp)}


def child_main(args: argparse.Namespace) -> None:
    run = child_recap if args.child == "recap" else child_inspect
    result = run(args.url, args.n, args.rounds, Path(args.tmp))
    Path(args.result).write_text(json.dumps(result))


# ---------------------------------------------------------------- the parent: sampling and the table
class TreeSampler(threading.Thread):
    """Snapshots of a process tree every SAMPLE_EVERY_S seconds, (wall time, {pid: sample})."""

    def __init__(self, root: int):
        super().__init__(daemon=True)
        self.root = root
        self.samples: list[tuple[float, dict[int, ProcSample]]] = []
        self._stop_event = threading.Event()

    def run(self) -> None:
        while not self._stop_event.is_set():
            t0 = time.time()
            snap = snapshot(self.root)
            if snap:
                self.samples.append(((t0 + time.time()) / 2, snap))
            self._stop_event.wait(SAMPLE_EVERY_S)

    def stop(self) -> None:
        self._stop_event.set()
        self.join()

    def peak_pss(self) -> int:
        return max((sum(s.pss for s in snap.values()) for _, snap in self.samples), default=0)

    def cpu_between(self, a: float, b: float) -> float:
        """CPU seconds the tree spent between wall times a and b: each process's CPU time
        interpolated between the samples around a and b (0 before it was first seen, its last
        figure after it was last seen)."""
        series: dict[int, list[tuple[float, float]]] = {}
        for t, snap in self.samples:
            for pid, s in snap.items():
                series.setdefault(pid, []).append((t, s.cpu_s))
        return sum(_at(points, b) - _at(points, a) for points in series.values())


def _at(points: list[tuple[float, float]], t: float) -> float:
    if t < points[0][0]:
        return 0.0
    for (t0, v0), (t1, v1) in zip(points, points[1:]):
        if t0 <= t <= t1:
            return v0 + (v1 - v0) * (t - t0) / (t1 - t0) if t1 > t0 else v1
    return points[-1][1]


def inspect_versions(python: str) -> str | None:
    """``inspect_ai X, openai Y`` of that interpreter, or None when it cannot run Inspect's OpenAI
    provider (not there, Inspect not installed, or an openai older than the one it checks for)."""
    probe = (
        "import inspect_ai, openai\n"
        "from inspect_ai.model._providers.providers import validate_openai_client\n"
        "validate_openai_client('OpenAI API')\n"
        "print(f'inspect_ai {inspect_ai.__version__}, openai {openai.__version__}')"
    )
    try:
        done = subprocess.run([python, "-c", probe], capture_output=True, text=True, timeout=120)
    except OSError:
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def server_prompt_tokens(url: str) -> float:
    """Mean prompt tokens of the answered calls, from the server's own log."""
    with urllib.request.urlopen(url.removesuffix("/v1") + "/fake/log", timeout=30) as resp:
        calls = json.load(resp)["calls"]
    tokens = [c["prompt_tokens"] for c in calls if c["status"] == 200]
    return statistics.mean(tokens) if tokens else float("nan")


def measure(side: str, n: int, rounds: int, python: str) -> dict[str, Any]:
    """One side at N in flight: its child run (under ``python``), sampled from here, and the
    figures of its window."""
    server, url = start_server()
    try:
        with tempfile.TemporaryDirectory(prefix=f"vs-inspect-{side}-") as tmp:
            result_file, log_file = Path(tmp) / "result.json", Path(tmp) / "child.log"
            env = dict(os.environ)
            if side == "inspect":  # what Inspect keeps in the user's data and cache folders (its trace
                # log, the running samples' buffer) lands in the run folder, counted with its log
                env["XDG_DATA_HOME"] = str(Path(tmp) / "run" / "xdg-data")
                env["XDG_CACHE_HOME"] = str(Path(tmp) / "run" / "xdg-cache")
            log = log_file.open("w")
            child = subprocess.Popen(
                [python, __file__, "--child", side, "--n", str(n), "--rounds", str(rounds), "--url", url]
                + ["--tmp", str(Path(tmp) / "run"), "--result", str(result_file)],
                cwd=ROOT,
                env=env,
                stdout=log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
            sampler = TreeSampler(child.pid)
            sampler.start()
            try:
                rc = child.wait(timeout=CHILD_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                os.killpg(child.pid, signal.SIGKILL)
                child.wait()
                rc = -9
            sampler.stop()
            log.close()
            if rc != 0 or not result_file.exists():
                lines = [line for line in log_file.read_text(errors="replace").splitlines() if line.strip()]
                return {"side": side, "n": n, "status": f"failed (exit {rc}): {lines[-1] if lines else 'no output'}"}
            result = json.loads(result_file.read_text())
        prompt_tokens = server_prompt_tokens(url)
    finally:
        server.terminate()
        server.wait(10)
    ends = [tuple(e) for e in result["ends"]]
    if len(ends) <= n:
        return {"side": side, "n": n, "status": f"{result['status']} ({len(ends)} episodes: none after warm-up)"}
    a, b = ends[n - 1][0], ends[-1][0]
    measured = ends[n:]
    calls = sum(c for _, c in measured)
    span = b - a
    ideal = n * 60 / (CALLS * LATENCY)
    return {
        "side": side,
        "n": n,
        "episodes": len(ends),
        "eps_per_min": len(measured) / span * 60,
        "ideal": ideal,
        "cpu_ms_per_call": sampler.cpu_between(a, b) / max(calls, 1) * 1000,
        "calls_per_episode": calls / len(measured),
        "peak_pss_mb": sampler.peak_pss() / 2**20,
        "prompt_tokens": prompt_tokens,
        "written_mb": result["written"] / 2**20,
        "status": result["status"],
    }


HEADER = (
    f"{'in flight':>9} {'side':>7} {'episodes':>8} {'ep/min':>7} {'ideal':>6} {'% ideal':>7} {'CPU ms/call':>11} "
    f"{'peak PSS MB':>11} {'MB/episode':>10} {'prompt tok':>10} {'calls/ep':>8} {'written MB':>10}  status"
)


def row(r: dict[str, Any]) -> str:
    if "eps_per_min" not in r:
        return f"{r['n']:>9} {r['side']:>7} {'-':>8}  {r['status']}"
    return (
        f"{r['n']:>9} {r['side']:>7} {r['episodes']:>8} {r['eps_per_min']:>7.0f} {r['ideal']:>6.0f} "
        f"{r['eps_per_min'] / r['ideal']:>7.0%} {r['cpu_ms_per_call']:>11.1f} {r['peak_pss_mb']:>11.0f} "
        f"{r['peak_pss_mb'] / r['n']:>10.1f} {r['prompt_tokens']:>10.0f} {r['calls_per_episode']:>8.1f} "
        f"{r['written_mb']:>10.1f}  {r['status']}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--concurrency", type=int, nargs="+", default=[8, 32, 64, 128], help="episodes in flight")
    ap.add_argument("--rounds", type=int, default=3, help="episodes per slot in each measurement (the first is warm-up)")
    ap.add_argument("--only", choices=SIDES, help="run one side only")
    ap.add_argument("--inspect-python", help=f"the interpreter with Inspect AI installed (default {INSPECT_PYTHON})")
    # the child process of one measurement (internal)
    ap.add_argument("--child", choices=SIDES, help=argparse.SUPPRESS)
    ap.add_argument("--n", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--url", help=argparse.SUPPRESS)
    ap.add_argument("--tmp", help=argparse.SUPPRESS)
    ap.add_argument("--result", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child_main(args)
        return
    if args.rounds < 2 or min(args.concurrency) < 1:
        sys.exit("vs_inspect: --rounds must be at least 2 (the first round is warm-up) and --concurrency at least 1")
    sides = [args.only] if args.only else list(SIDES)
    inspect_python = args.inspect_python or os.environ.get("RECAP_INSPECT_PYTHON") or str(INSPECT_PYTHON)
    if "inspect" in sides:
        versions = inspect_versions(inspect_python)
        if versions is None:
            sys.exit(
                f"vs_inspect: no Inspect AI at {inspect_python}: python3.11 -m venv .venv-inspect && "
                ".venv-inspect/bin/pip install -r bench/requirements-inspect.txt (or --inspect-python PATH, or --only recap)"
            )
    if "inspect" in sides:
        print(f"inspect side: {inspect_python} ({versions})")
    print(
        f"host CPUs {os.cpu_count()}; fake server latency {LATENCY * 1000:.0f} ms in its own process; {CALLS} calls per "
        f"episode; {args.rounds} episodes per slot (first round = warm-up, not timed)",
        flush=True,
    )
    print(HEADER, flush=True)
    for n in args.concurrency:
        for side in sides:
            python = inspect_python if side == "inspect" else sys.executable
            print(row(measure(side, n, args.rounds, python)), flush=True)
    print(
        "ideal = in flight x 60 s / (calls x latency); CPU ms/call and peak PSS: the side's whole process tree\n"
        "(recap: driver + Ray cluster + actors; inspect: its one process); prompt tok = mean prompt tokens per call\n"
        "counted by the server; written MB: recap's run folder (Parquet + manifests) vs Inspect's .eval log and trace"
    )


if __name__ == "__main__":
    main()
