"""The shipped configuration files: cluster.yaml against Ray's launcher schema, the example
sweep files against the sweep schema."""

from __future__ import annotations

from pathlib import Path

import yaml

from pipeline.spec import load_spec

REPO = Path(__file__).resolve().parents[2]


def test_cluster_yaml_is_a_valid_launcher_file_that_installs_the_project():
    from ray.autoscaler._private.util import prepare_config, validate_config

    raw = yaml.safe_load((REPO / "cluster.yaml").read_text())
    config = prepare_config(raw)
    validate_config(config)  # raises on a schema error
    assert set(config["available_node_types"]) == {"head", "cpu_worker"}
    assert config["head_node_type"] == "head"
    assert raw["file_mounts"]["~/recap-eval"] == "."
    assert any("pip install" in c and "~/recap-eval[alfworld]" in c for c in raw["setup_commands"])
    assert any("ray start --head" in c for c in raw["head_start_ray_commands"])
    assert any("--address=$RAY_HEAD_IP:6379" in c for c in raw["worker_start_ray_commands"])


def test_example_sweeps_parse():
    demo, _ = load_spec(REPO / "examples" / "demo.yaml")
    assert [m.model for m in demo.models] == ["offline/expert"]
    assert [m.name for m in demo.methods] == ["recap", "react"]
    assert [(e.benchmark, e.tasks) for e in demo.environments] == [
        ("robotouille", ["synchronous/2", "synchronous/6", "asynchronous/1", "asynchronous/5"]),
        ("alfworld", ["heat", "clean"]),
    ]
    real, _ = load_spec(REPO / "examples" / "real-model.yaml")
    assert real.run_cap_usd == 40.0 and real.models[0].cap_usd == 20.0
    assert [m.name for m in real.methods] == ["recap", "recap-no-think", "react"]
