"""The served-model example (examples/served/): the sweep parses with its four models, three served
by vLLM with the GPUs its cluster file declares, and the cluster file is a valid launcher file
with GPU worker nodes; and a session removes what an earlier session of its run left deployed."""

from __future__ import annotations

from pathlib import Path

import yaml

from pipeline.serving import service
from pipeline.serving.checks import check_cluster
from pipeline.serving.engines import serve_plan
from pipeline.spec import load_spec

REPO = Path(__file__).resolve().parents[3]
SERVED = REPO / "examples" / "served"


def test_the_cross_model_example_serves_three_open_weight_models_with_vllm():
    spec, _ = load_spec(SERVED / "cross-model-vllm.yaml")
    assert [m.name for m in spec.models] == ["gpt-4o", "qwen2.5-7b", "llama-3.1-8b", "deepseek-v2-lite"]
    assert spec.models[0].serve is None
    plans = [serve_plan(m) for m in spec.models[1:]]
    assert [(p.engine, p.weights, p.replicas, p.gpus, p.served_name) for p in plans] == [
        ("vllm", "Qwen/Qwen2.5-7B-Instruct", 2, 1, "Qwen2.5-7B-Instruct"),
        ("vllm", "meta-llama/Llama-3.1-8B-Instruct", 1, 1, "Llama-3.1-8B-Instruct"),
        ("vllm", "deepseek-ai/DeepSeek-V2-Lite-Chat", 1, 2, "DeepSeek-V2-Lite-Chat"),
    ]
    assert [p.usd_per_replica_hour for p in plans] == [1.20, 1.20, 2.40]  # gpu_hour x GPUs of a replica
    assert [p.concurrency for p in plans] == [64, 32, 16]
    # recap estimate prices Qwen from the sweep's tokens/s; the other two need a probe
    assert [m.serve.tokens_per_s for m in spec.models[1:] if m.serve is not None] == [1000, None, None]
    # the cluster file's GPU workers hold the five GPUs the replicas ask for
    raw = yaml.safe_load((SERVED / "cluster.yaml").read_text())
    gpu = raw["available_node_types"]["gpu_worker"]
    gpus = gpu["min_workers"] * gpu["resources"]["GPU"]
    check_cluster(spec, {"CPU": 64, "GPU": gpus}, workers=spec.workers)


def test_the_served_cluster_file_is_a_valid_launcher_file_with_gpu_workers():
    from ray.autoscaler._private.util import prepare_config, validate_config

    raw = yaml.safe_load((SERVED / "cluster.yaml").read_text())
    config = prepare_config(raw)
    validate_config(config)
    assert set(config["available_node_types"]) == {"head", "cpu_worker", "gpu_worker"}
    assert config["available_node_types"]["gpu_worker"]["resources"]["GPU"] == 4
    assert any("~/recap-eval[serve]" in c and "vllm" in c for c in raw["setup_commands"])


def test_a_session_removes_the_applications_an_earlier_session_of_its_run_left(monkeypatch):
    """A killed driver on a joined cluster leaves its Serve applications: the next session of the
    run (the run folder's lock held: no live driver owns them) deletes those of its run, only."""
    import ray.serve

    deleted: list[str] = []
    events: list[tuple[str, dict]] = []
    monkeypatch.setattr(service, "serve_apps", lambda: dict.fromkeys(["recap-r1-0", "recap-r1-1", "recap-r2-0", "someone-else"]))
    monkeypatch.setattr(ray.serve, "delete", deleted.append)
    spec, _ = load_spec(SERVED / "cross-model-vllm.yaml")
    served = service.ServedModels(spec, "r1", lambda kind, **detail: events.append((kind, detail)))
    assert served.remove_leftovers() == 2
    assert deleted == ["recap-r1-0", "recap-r1-1"]
    assert events == [
        ("serve_leftover_removed", {"severity": "warning", "app": "recap-r1-0"}),
        ("serve_leftover_removed", {"severity": "warning", "app": "recap-r1-1"}),
    ]
