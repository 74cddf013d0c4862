"""The chaos lab: what every scenario shares (Ray, fake servers, sweep files, table reads, money).

A *scenario* (``tests/pipeline/chaos/{kills,faults,folders,inputs,exposure}.py``) plays one kind of
failure against the real pipeline - driver, episode workers, LLM gateway, sink, run folder -
with the offline test-double models and the loopback fake OpenAI server, and returns a
:class:`ScenarioResult`: how many randomised runs it made, how many passed every check, and
three figures a user running overnight on a paid API cares about:

* ``lost`` - units of the plan that end without a completed terminal row, plus finished
  episodes whose terminal row or records did not reach the run folder;
* ``duplicated`` - terminal rows beyond one per unit (and episode ids used twice);
* ``overspend_usd`` - money beyond what the run may spend: past a cap (as the *provider*
  billed it, from the fake server's own log), or paid again for a unit already completed.

``tests/pipeline/chaos/lab.py`` prints these; ``tests/pipeline/chaos/test_chaos_slow.py`` asserts them.
"""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys
import time
from collections import Counter, defaultdict
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[3]
#: the variable holding the fake API key of every fake-server model of the chaos sweeps
KEY_ENV = "RECAP_CHAOS_KEY"
FAKE_KEY = "sk-chaos-FAKEKEY-7f3a9c21d4e8b605"
FAKE_MODEL = "openai/fake-gpt"
#: output tokens per call (bounds each call's worst case, so caps bind after a few calls)
MAX_TOKENS = 64

os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")


# --------------------------------------------------------------------------------------------
# results
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Check:
    name: str
    ok: bool
    detail: str = ""

    def __str__(self) -> str:
        return f"{'ok ' if self.ok else 'FAIL'} {self.name}" + (f": {self.detail}" if self.detail else "")


@dataclass
class ScenarioResult:
    name: str
    runs: int = 0
    passed: int = 0
    lost: int = 0
    duplicated: int = 0
    #: None where no cap or payment rule applies to the scenario
    overspend_usd: float | None = None
    notes: list[str] = field(default_factory=list)
    checks: list[Check] = field(default_factory=list)
    wall_s: float = 0.0
    _run_ok: bool = True

    def check(self, name: str, ok: bool, detail: Any = "") -> bool:
        self.checks.append(Check(name, bool(ok), str(detail)))
        self._run_ok = self._run_ok and bool(ok)
        return bool(ok)

    def begin_run(self) -> None:
        self._run_ok = True

    def end_run(self) -> None:
        self.runs += 1
        self.passed += int(self._run_ok)

    def add_overspend(self, usd: float) -> None:
        self.overspend_usd = (self.overspend_usd or 0.0) + max(0.0, usd)

    @property
    def failures(self) -> list[Check]:
        return [c for c in self.checks if not c.ok]

    @property
    def ok(self) -> bool:
        return self.runs > 0 and self.passed == self.runs and not self.failures


# --------------------------------------------------------------------------------------------
# the lab: one Ray session, fake servers, folders
# --------------------------------------------------------------------------------------------
class Lab:
    """Shared state of one chaos session (a bench invocation or a pytest module)."""

    def __init__(self, root: Path, seed: int = 0, log: Callable[[str], None] | None = None) -> None:
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)
        self.seed = seed
        self.log = log or (lambda msg: None)
        self._servers: list[Any] = []
        self._ray_started = False
        self._address: str | None = None

    def rng(self, salt: str) -> random.Random:
        return random.Random(f"{self.seed}:{salt}")

    def folder(self, name: str) -> Path:
        path = self.root / name
        path.mkdir(parents=True, exist_ok=True)
        return path

    def server(self, **config: Any) -> Any:
        """A loopback fake OpenAI server (stopped by :meth:`close`)."""
        from workers.llm.offline.fake_server import FakeServer, FakeServerConfig

        server = FakeServer(FakeServerConfig(**config))
        server.start_in_thread()
        self._servers.append(server)
        return server

    def ray_address(self) -> str:
        """The shared local Ray of this session (started once); drivers run in-process or join
        it with ``--address``."""
        import ray

        from pipeline.raysetup import init_ray
        from pipeline.spec import RaySpec

        if self._address is None:
            os.environ[KEY_ENV] = FAKE_KEY  # the gateway actors read it at call time
            old = os.environ.get("PYTHONPATH")
            os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), old) if p)
            self._ray_started = init_ray(RaySpec(num_cpus=2))
            self._address = ray.get_runtime_context().gcs_address
        return self._address

    def env(self, **extra: str) -> dict[str, str]:
        """Environment of a CLI subprocess: this checkout importable, the fake key set."""
        old = os.environ.get("PYTHONPATH")
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in (str(REPO), old) if p))
        env[KEY_ENV] = FAKE_KEY
        env.update(extra)
        return env

    def cli(self, args: Sequence[str], **popen: Any) -> subprocess.Popen:
        """``recap ARGS`` as a process of its own."""
        return subprocess.Popen([sys.executable, "-m", "pipeline.cli", *args], cwd=REPO, **popen)

    def close(self) -> None:
        for s in self._servers:
            try:
                s.stop_thread()
            except Exception:
                pass
        self._servers.clear()
        if self._ray_started:
            from pipeline.raysetup import shutdown_ray

            shutdown_ray()
            self._ray_started = False
            self._address = None


# --------------------------------------------------------------------------------------------
# sweep files
# --------------------------------------------------------------------------------------------
def blocks(n: int) -> list[str]:
    """``n`` small blocksworld instances (3 and 4 blocks, alternating)."""
    return [f"blocksworld/{3 + i % 2}@{1 + i // 2}" for i in range(n)]


def fake_model(
    url: str, *, label: str | None = None, key_env: str = KEY_ENV, max_tokens: int = MAX_TOKENS, **transport: Any
) -> str:
    """A sweep's model entry for the fake server (``transport``: rpm, retries, timeout_s ...)."""
    lines = [
        f"  - model: {FAKE_MODEL}",
        f"    api_base: {url}",
        f"    api_key_env: {key_env}",
        f"    params: {{max_tokens: {max_tokens}}}",
    ]
    if label:
        lines.append(f"    label: {label}")
    lines += [f"    {k}: {json.dumps(v)}" for k, v in transport.items()]
    return "\n".join(lines) + "\n"


def sweep(
    out: Path,
    models: str,
    instances: Sequence[str],
    *,
    run: str | None = None,
    seeds: Sequence[int] = (0,),
    method: str = "react",
    llm_calls: int = 6,
    workers: int = 3,
    extra: str = "",
) -> str:
    return (
        f"run: {run or out.name}\noutput: {out}\nmodels:\n{models}"
        f"methods: [{{method: {method}}}]\n"
        f"environments: [{{benchmark: blocksworld, instances: [{', '.join(instances)}]}}]\n"
        f"seeds: {list(seeds)}\nlimits: {{llm_calls: {llm_calls}}}\nworkers: {workers}\n{extra}"
    )


def run_driver(text: str, *, hooks: Any = None, backend: Any = None, overrides: dict[str, Any] | None = None) -> tuple[Any, Any]:
    """One in-process driver session on the lab's Ray: (summary, prepared)."""
    from pipeline.driver import Driver, prepare
    from pipeline.gateway_backend import make_backend
    from pipeline.spec import parse_spec, with_overrides

    spec = with_overrides(parse_spec(text, "sweep.yaml"), **(overrides or {}))
    prepared = prepare(spec, text)
    summary = Driver(prepared, backend or make_backend(spec), progress="off", hooks=hooks).run()
    return summary, prepared


# --------------------------------------------------------------------------------------------
# what a run folder holds
# --------------------------------------------------------------------------------------------
def rows(out: Path, table: str, columns: list[str] | None = None) -> list[dict[str, Any]]:
    from pipeline.store import RunStore

    data, _ = RunStore(out).read_table(table, columns)
    return data.to_pylist()


def plan_ids(out: Path) -> list[str]:
    return [u["unit_id"] for u in json.loads((Path(out) / "plan.json").read_text())["units"]]


@dataclass
class Terminal:
    """The episodes table seen through the completion rule (a row neither ``budget_exhausted``
    nor an infrastructure failure, :func:`pipeline.resume.infra_failure`)."""

    rows: list[dict[str, Any]]
    plan: list[str]

    @property
    def completed(self) -> dict[str, dict[str, Any]]:
        """unit_id -> its (latest) completed terminal row."""
        from pipeline.resume import is_final

        out: dict[str, dict[str, Any]] = {}
        for r in sorted(self.rows, key=lambda r: r["attempt"]):
            if is_final(r["end_reason"], r["error"]):
                out[r["unit_id"]] = r
        return out

    @property
    def failed(self) -> dict[str, dict[str, Any]]:
        """unit_id -> its latest row, for units whose latest row is an infrastructure failure
        (ended, not done: the next resume retries them)."""
        from pipeline.resume import infra_failure

        done = self.completed
        out: dict[str, dict[str, Any]] = {}
        for r in sorted(self.rows, key=lambda r: r["attempt"]):
            if r["unit_id"] not in done and infra_failure(r["end_reason"], r["error"]) is not None:
                out[r["unit_id"]] = r
        return out

    @property
    def lost(self) -> list[str]:
        """Units without a terminal row that ends them (completed, or failed and retryable)."""
        done, failed = self.completed, self.failed
        return [u for u in self.plan if u not in done and u not in failed]

    @property
    def duplicated(self) -> int:
        from pipeline.resume import is_final

        per_unit = Counter(r["unit_id"] for r in self.rows if is_final(r["end_reason"], r["error"]))
        per_episode = Counter(r["episode_id"] for r in self.rows)
        return sum(n - 1 for n in per_unit.values()) + sum(n - 1 for n in per_episode.values())


def terminal(out: Path) -> Terminal:
    return Terminal(rows(out, "episodes"), plan_ids(out))


def calls_by_episode(out: Path) -> dict[str, list[dict[str, Any]]]:
    by: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for r in rows(out, "llm_calls"):
        by[r["episode_id"]].append(r)
    return by


def events(out: Path, kind: str | None = None) -> list[dict[str, Any]]:
    evs = rows(out, "events")
    for e in evs:
        e["detail"] = json.loads(e["detail"] or "{}")
    return [e for e in evs if kind is None or e["kind"] == kind]


# --------------------------------------------------------------------------------------------
# money: the ledger journal (what the gateway committed) and the provider's own bill
# --------------------------------------------------------------------------------------------
def journal(out: Path) -> list[dict[str, Any]]:
    path = Path(out) / "gateway" / "ledger.jsonl"
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def episode_of_key(call_key: str) -> str:
    return call_key.rsplit("#", 1)[0]


def journal_spend(entries: Iterable[dict[str, Any]]) -> dict[str, int]:
    """episode_id -> pico settled (actual costs, worst cases charged, orphans)."""
    out: dict[str, int] = defaultdict(int)
    for e in entries:
        if e.get("op") == "settle":
            out[episode_of_key(e["key"])] += int(e["pico"])
    return out


def reserved_episodes(entries: Iterable[dict[str, Any]]) -> set[str]:
    """Episodes for which at least one call was reserved (about to be sent)."""
    return {episode_of_key(e["key"]) for e in entries if e.get("op") == "reserve" and not e["key"].startswith("lease:")}


def fake_price() -> Any:
    from workers.llm.pricing import default_prices

    price = default_prices().get(FAKE_MODEL)
    assert price is not None, f"{FAKE_MODEL} has no price in workers/pricing"
    return price


def provider_bill_usd(server: Any, statuses: Iterable[int] = (200,)) -> float:
    """What the fake provider would bill: every answered request at the model's price."""
    from workers.llm.pricing import pico_to_usd

    price = fake_price()
    keep = set(statuses)
    pico = sum(
        price.cost_pico(c.prompt_tokens, c.cached_tokens, c.completion_tokens)
        for c in server.log
        if c.status in keep and c.mode == "ok"
    )
    return pico_to_usd(pico)


def wait_until(pred: Callable[[], bool], timeout_s: float, every_s: float = 0.2) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(every_s)
    return pred()


def unit_of(episode_id: str) -> str:
    return episode_id.rsplit("-", 1)[0]


def attempt_of(episode_id: str) -> int:
    return int(episode_id.rsplit("-", 1)[1])
