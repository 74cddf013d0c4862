"""An episode worker process imports only what an episode needs (issue 37, item 3).

Every module an episode worker loads costs each worker process its memory: pyarrow and numpy
(~30 MB), litellm (~200 MB with its model map) or duckdb belong to the sink, the gateway and the
reports, never to a worker. The check runs in a fresh interpreter, does what a worker process
does (import the worker module, unpickle the driver's client factory and a gateway client,
build an agent and an environment and play a unit through the offline expert's answers) and
lists the heavy modules loaded.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
HEAVY = ("pyarrow", "numpy", "litellm", "duckdb", "pandas")

SCRIPT = textwrap.dedent(
    """
    import json, pickle, sys

    from recap.llm import LLMResponse
    from schemas.outcomes import UnitWork
    from workers.episode_worker import ClientTable, EpisodeRunner, build_agent
    from workers.llm.offline.expert import expert_reply
    from workers.llm.offline.knobs import Knobs
    import workers.gateway.client  # what unpickling the factory's GatewayClient imports


    class Expert:
        # the offline expert's answer from the plan the episode client puts in the hints
        def complete(self, request):
            reply = expert_reply(request.hints, Knobs(), request.call_key)
            return LLMResponse(json.dumps(reply), "offline/expert", test_double=True)


    factory = pickle.loads(pickle.dumps(ClientTable({"expert": Expert()}, writes_llm_calls=False)))
    rows = {}

    def send(batch):
        for table, items in batch.items():
            rows.setdefault(table, []).extend(items)

    runner = EpisodeRunner("w1", "run-x", factory, send=send, wait=lambda ref: None)
    ends = []
    for item in json.loads(sys.argv[1]):
        agent = build_agent(item["method"], benchmark=item["instance"].split("/")[0])
        work = UnitWork(
            unit_id="u-" + item["method"],
            instance_id=item["instance"],
            method=item["method"],
            method_config=agent.config.to_json(),
            model_label="expert",
            model="offline/expert",
            sampling_seed=1,
            step_multiplier=4.0,
        )
        out = runner.run_unit(work, 1)
        ends.append([item["instance"], item["method"], out.result.end_reason if out.result else repr(out.crash)])
    print(json.dumps({"ends": ends, "tables": sorted(rows), "heavy": sorted(m for m in HEAVY if m in sys.modules)}))
    """
).replace("HEAVY", repr(HEAVY))


def _play(units: list[dict[str, str]], env: dict[str, str] | None = None) -> dict:
    import os

    proc = subprocess.run(
        [sys.executable, "-c", SCRIPT, json.dumps(units)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "PYTHONPATH": str(ROOT), **(env or {})},
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_a_blocksworld_episode_loads_no_heavy_module():
    got = _play([{"method": "react", "instance": "blocksworld/3@1"}, {"method": "recap", "instance": "blocksworld/4@2"}])
    assert got["ends"] == [["blocksworld/3@1", "react", "success"], ["blocksworld/4@2", "recap", "success"]]
    assert "messages" in got["tables"] and "steps" in got["tables"]
    assert got["heavy"] == []


def test_a_robotouille_episode_loads_no_heavy_module():
    data = (ROOT / ".." / "shared" / "data" / "robotouille").resolve()
    assert (data / "domain" / "robotouille.json").is_file(), f"Robotouille data missing at {data}"
    instance = "robotouille/synchronous/0_cheese_sandwich@126"
    got = _play([{"method": "react", "instance": instance}], env={"ROBOTOUILLE_DATA": str(data)})
    assert got["ends"] == [[instance, "react", "success"]]
    assert got["heavy"] == []


def test_pyarrow_loads_on_the_first_schema():
    """What the worker never does, the sink and the readers do: a table's Arrow schema imports pyarrow."""
    proc = subprocess.run(
        [sys.executable, "-c", "import sys, schemas.tables as t; t.TABLES['episodes']; print('pyarrow' in sys.modules)"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.stdout.strip() == "True", proc.stderr[-2000:]
