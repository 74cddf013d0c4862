"""What a run's processes do NOT import (issue 37, item 3: memory per episode and of the fixed actors).

An episode worker holds no Arrow table, pydantic model or litellm object: its rows reach the
sink as plain data and its model calls go through the gateway. pyarrow with numpy, pydantic,
pandas and litellm together are ~40-170 MB a process, so they must stay out of it - and out of
the budget actor - even though Ray imports the module of every actor class whose handle a
process receives (the sink's, the gateway's) and builds a serialisation context that registers
serialisers for pyarrow and pydantic (:mod:`workers.worker_setup`). A writer of part files (the
sink, every gateway) needs pyarrow but not pandas (:func:`schemas.parts.arrow_without_pandas`).

Checked in fresh processes (a subprocess, an actor of the test cluster started with the
pipeline's own ``runtime_env``), since the test process itself has imported all of them.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

#: what an episode worker (and the budget actor) must not load
HEAVY = ("pyarrow", "numpy", "pandas", "pydantic", "litellm", "openai", "tiktoken")


def _loaded_after(code: str) -> list[str]:
    """The HEAVY modules a fresh interpreter holds after running ``code``."""
    script = f"import json, sys\n{code}\nprint(json.dumps(sorted(m for m in {HEAVY!r} if m in sys.modules)))"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "LITELLM_LOCAL_MODEL_COST_MAP": "True"}
    out = subprocess.run([sys.executable, "-c", script], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_the_actor_modules_an_episode_worker_loads_bring_nothing_heavy():
    """The modules Ray imports in an episode worker: its own class's, and those of the actors whose
    handles it holds (sink, budget and gateway share workers/gateway/actors.py)."""
    code = "import workers.episode_worker, workers.sink, workers.gateway.actors, schemas.parts, schemas.versions"
    assert _loaded_after(code) == []


def test_a_part_writer_loads_pyarrow_but_not_pandas(tmp_path):
    code = (
        "import time\n"
        "from schemas.parts import PartWriter, read_table\n"
        "from schemas.records import EventRecord\n"
        f"PartWriter({str(tmp_path)!r}, 'w1').write_records('run-1', "
        "[EventRecord(ts=1.0, source='gateway', kind='ledger_restored', severity='warning', detail='{}')])\n"
        "assert 'pyarrow' in sys.modules"
    )
    assert _loaded_after(code) == ["numpy", "pyarrow"]
    # the rows are the same as ever: read back in this process
    from schemas.parts import read_table

    table, bad = read_table(tmp_path, "events")
    assert bad == []
    assert [(r["run_id"], r["source"], r["kind"], r["severity"], r["detail"]) for r in table.to_pylist()] == [
        ("run-1", "gateway", "ledger_restored", "warning", "{}")
    ]


def test_importing_litellm_points_tiktoken_at_its_bundled_encodings_without_loading_one():
    """import_litellm sets TIKTOKEN_CACHE_DIR as litellm's default_encoding module does, but
    without importing it: that module loads cl100k_base (~38 MB) in the gateway and the driver,
    whatever their models. An OpenAI model's prompt is still counted by its tokenizer, from the
    bundled file (no download: the folder is litellm's)."""
    code = (
        "import os\n"
        "from workers.llm.litellm_import import import_litellm\n"
        "litellm = import_litellm()\n"
        "from importlib import resources\n"
        "bundled = str(resources.files(litellm).joinpath('litellm_core_utils/tokenizers'))\n"
        "print(json.dumps([os.environ.get('TIKTOKEN_CACHE_DIR') == bundled, "
        "'litellm.litellm_core_utils.default_encoding' in sys.modules, 'tiktoken.registry' in sys.modules "
        "and bool(sys.modules['tiktoken.registry'].ENCODINGS)]))\n"
        "from workers.llm.tokens import count_prompt_tokens\n"
        "print(json.dumps(count_prompt_tokens('openai/gpt-4o', [{'role': 'user', 'content': 'hi'}]).source))"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT), "LITELLM_LOCAL_MODEL_COST_MAP": "True"}
    env.pop("TIKTOKEN_CACHE_DIR", None)
    env.pop("CUSTOM_TIKTOKEN_CACHE_DIR", None)
    out = subprocess.run(
        [sys.executable, "-c", "import json, sys\n" + code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stdout.strip().splitlines()
    assert json.loads(lines[-2]) == [True, False, False]
    assert json.loads(lines[-1]) == "tokenizer"


@pytest.mark.usefixtures("cluster_env")
@pytest.mark.parametrize("how", ["the pipeline's (none: the cluster's environment)", "runtime_env()"])
def test_an_actor_holding_the_sink_and_budget_handles_loads_nothing_heavy(tmp_path, how):
    """A fresh actor started like the episode workers is handed the run's sink and budget actors,
    calls them, and imports the episode worker's module: still none of HEAVY in its process. Ray's
    setup hook runs either way: from the local cluster's environment, as a run's actors start
    (actor_runtime_env() is None there), or from an explicit runtime_env (a joined cluster)."""
    import ray

    from pipeline.raysetup import actor_runtime_env, runtime_env
    from workers.gateway.actors import BudgetActor
    from workers.sink import sink_actor

    env = runtime_env() if how == "runtime_env()" else actor_runtime_env()
    assert (env is None) == (how != "runtime_env()")
    sink = sink_actor(env, max_restarts=0).remote(str(tmp_path / "run"), "run-1")
    budget = BudgetActor.options(runtime_env=env).remote(str(tmp_path / "ledger"))

    @ray.remote(num_cpus=0)
    class Probe:
        def __init__(self, handles: list) -> None:
            self.handles = handles

        def loaded(self) -> tuple[list[str], dict, dict]:
            import workers.episode_worker  # noqa: F401  # the episode worker's own module

            sink_stats = ray.get(self.handles[0].stats.remote(), timeout=60)
            budget_stats = ray.get(self.handles[1].stats.remote(), timeout=60)
            heavy = sorted(m for m in HEAVY if m in sys.modules)
            return heavy, sink_stats, budget_stats

    probe = Probe.options(runtime_env=env).remote([sink, budget])
    try:
        heavy, sink_stats, budget_stats = ray.get(probe.loaded.remote(), timeout=180)
    finally:
        for actor in (probe, sink, budget):
            ray.kill(actor)
    assert heavy == []
    assert (sink_stats["rows_written"], budget_stats["spent_usd"], budget_stats["open_reservations"]) == (0, 0.0, 0)
