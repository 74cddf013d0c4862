"""A sweep serving vLLM or SGLang on a local cluster starts it collecting metrics, with Ray's own
dashboard agent: its replicas' queue is read from Ray's metrics export (workers/serving/queue_source.py,
``ray_metrics``). Every other sweep keeps the lean cluster (no metrics, the idle agent)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from pipeline.raysetup import needs_metrics
from pipeline.spec import parse_spec

REPO = Path(__file__).resolve().parents[2]
BASE = """run: mc
output: {out}
methods: [{{method: react}}]
environments: [{{benchmark: blocksworld, tasks: ["3"]}}]
workers: 2
models: [{models}]
"""


@pytest.mark.parametrize(
    ("models", "wanted"),
    [
        ("{model: openai/qwen, serve: {engine: vllm, weights: Qwen/Qwen2.5-7B-Instruct}}", True),
        ("{model: offline/tiny}, {model: openai/ds, serve: {engine: sglang, weights: deepseek-ai/DeepSeek-V2-Lite-Chat}}", True),
        ("{model: openai/smol, serve: {engine: llama.cpp, weights: /w/smol.gguf}}", False),
        ("{model: offline/expert, serve: {engine: test-double}}", False),
        ("{model: offline/tiny}", False),
    ],
)
def test_only_a_sweep_serving_vllm_or_sglang_needs_metrics(tmp_path, models, wanted):
    assert needs_metrics(parse_spec(BASE.format(out=tmp_path / "run", models=models), "sweep.yaml")) is wanted


PROBE = r"""
import json
from pathlib import Path
from pipeline.raysetup import init_ray, shutdown_ray
from pipeline.spec import RaySpec
from tests.pipeline.ray_procs import children, gcs_config, session_cluster
init_ray(RaySpec(num_cpus=1), metrics=True)
try:
    session, raylet = session_cluster()
    print(json.dumps({
        "config": gcs_config(session),
        "children": [" ".join(argv) for argv in children(raylet)],
        "export_port": next(Path(session).glob("metrics_export_port_*")).read_text(),
    }))
finally:
    shutdown_ray()
"""


def test_a_cluster_started_for_metrics_collects_them_with_rays_agent(tmp_path):
    done = subprocess.run([sys.executable, "-c", PROBE], cwd=REPO, capture_output=True, text=True, timeout=180)
    assert done.returncode == 0, done.stderr[-2000:]
    seen = json.loads(done.stdout.strip().splitlines()[-1])
    assert seen["config"]["enable_metrics_collection"] is True
    assert seen["config"]["task_events_report_interval_ms"] == 0  # the rest of the lean settings kept
    assert not [c for c in seen["children"] if "idle_dashboard_agent" in c]
    assert [c for c in seen["children"] if "dashboard/agent.py" in c or "ray::DashboardAgent" in c]
    assert int(seen["export_port"]) > 0  # a real metrics export port, not the idle agent's -1
