"""The served models' preflight: each refusal is one exact line, before anything is written or started
(pipeline/serving/checks.py), and the shape of ``models[].serve`` (pipeline/spec/serving.py)."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from pipeline.cli import main
from pipeline.errors import PreflightError, SpecError
from pipeline.preflight import preflight
from pipeline.serving import checks
from pipeline.serving.checks import check_cluster
from pipeline.spec import parse_spec

BASE = """run: pf
output: {out}
methods: [{{method: react}}]
environments: [{{benchmark: blocksworld, tasks: ["3"]}}]
workers: 2
"""


def spec_of(tmp_path: Path, model: str, extra: str = ""):
    return parse_spec(BASE.format(out=tmp_path / "run") + f"models: [{model}]\n" + extra, "sweep.yaml")


def refusal(tmp_path: Path, model: str, extra: str = "") -> str:
    with pytest.raises(PreflightError) as info:
        preflight(spec_of(tmp_path, model, extra))
    return str(info.value)


@pytest.fixture
def engines_installed(monkeypatch):
    """Every engine's modules present (this machine has none of vLLM, SGLang, llama.cpp)."""
    monkeypatch.setattr(checks, "installed", lambda module: True)


@pytest.fixture
def hub(tmp_path, monkeypatch):
    """An empty Hugging Face cache, then one holding a snapshot of Org/cached."""
    cache = tmp_path / "hf"
    (cache / "models--Org--cached" / "snapshots" / "abc").mkdir(parents=True)
    monkeypatch.setenv("HF_HUB_CACHE", str(cache))
    return cache


# -- engines installed ----------------------------------------------------------------------------
def test_ray_serve_missing_is_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(checks, "installed", lambda module: module != "ray.serve")
    assert refusal(tmp_path, "{model: offline/expert, serve: {replicas: 2}}") == (
        "models[0] (offline/expert): serve: Ray Serve is not installed (pip install 'recap-eval[serve]')"
    )


def test_vllm_missing_is_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(checks, "installed", lambda module: module not in ("vllm", "sglang", "llama_cpp"))
    assert refusal(tmp_path, "{model: openai/qwen, serve: {engine: vllm, weights: Qwen/Qwen2.5-7B-Instruct}}") == (
        "models[0] (openai/qwen): serve.engine vllm is not installed here (no module vllm; pip install 'ray[llm]' vllm)"
    )


def test_sglang_missing_is_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(checks, "installed", lambda module: module not in ("vllm", "sglang", "llama_cpp"))
    assert refusal(tmp_path, "{model: openai/qwen, label: q, serve: {engine: sglang, weights: Qwen/Qwen2.5-7B-Instruct}}") == (
        "models[0] (q): serve.engine sglang is not installed here (no module sglang; pip install 'ray[llm]' 'sglang[all]')"
    )


def test_llama_cpp_missing_is_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(checks, "installed", lambda module: module != "llama_cpp")
    assert refusal(tmp_path, "{model: openai/smol, serve: {engine: llama.cpp, weights: /w/smol.gguf}}") == (
        "models[0] (openai/smol): serve.engine llama.cpp is not installed here (no module llama_cpp; "
        "pip install 'llama-cpp-python[server]')"
    )


def test_the_engines_missing_here_are_refused_without_a_patch(tmp_path):
    """This machine as it is (no vLLM): the real lookup, not a patched one."""
    pytest.importorskip("ray.serve")
    if checks.installed("vllm"):
        pytest.skip("vLLM is installed here")
    assert refusal(tmp_path, "{model: openai/qwen, serve: {engine: vllm, weights: Qwen/Qwen2.5-7B-Instruct}}").startswith(
        "models[0] (openai/qwen): serve.engine vllm is not installed here (no module "
    )


# -- weights present --------------------------------------------------------------------------------
def test_weights_neither_local_nor_cached_are_refused(tmp_path, engines_installed, hub):
    assert refusal(tmp_path, "{model: openai/x, serve: {engine: vllm, weights: Org/absent}}") == (
        f"models[0] (openai/x): serve.weights Org/absent is neither a local path nor in the Hugging Face cache ({hub}); "
        "fetch it first (huggingface-cli download Org/absent)"
    )
    preflight(spec_of(tmp_path, "{model: openai/x, serve: {engine: vllm, weights: Org/cached}}"))  # in the cache: passes


def test_a_missing_local_path_is_refused(tmp_path, engines_installed, hub):
    gguf = tmp_path / "none.gguf"
    assert refusal(tmp_path, f"{{model: openai/s, serve: {{engine: llama.cpp, weights: {gguf}}}}}") == (
        f"models[0] (openai/s): serve.weights {gguf} is not a file here (llama.cpp serves a local GGUF file)"
    )
    gguf.write_bytes(b"GGUF")
    preflight(spec_of(tmp_path, f"{{model: openai/s, serve: {{engine: llama.cpp, weights: {gguf}}}}}"))


def test_llama_cpp_serves_gguf_files_only(tmp_path, engines_installed):
    folder = tmp_path / "weights"
    folder.mkdir()
    assert refusal(tmp_path, f"{{model: openai/s, serve: {{engine: llama.cpp, weights: {folder}}}}}") == (
        f"models[0] (openai/s): serve.weights: llama.cpp serves a GGUF file (*.gguf), got {folder}"
    )
    # a folder named like one, and a file of another format named like one: refused before any replica starts
    (tmp_path / "dir.gguf").mkdir()
    assert refusal(tmp_path, f"{{model: openai/s, serve: {{engine: llama.cpp, weights: {tmp_path / 'dir.gguf'}}}}}") == (
        f"models[0] (openai/s): serve.weights {tmp_path / 'dir.gguf'} is not a file here (llama.cpp serves a local GGUF file)"
    )
    (tmp_path / "st.gguf").write_bytes(b"\x00" * 64)  # a safetensors header, say
    assert refusal(tmp_path, f"{{model: openai/s, serve: {{engine: llama.cpp, weights: {tmp_path / 'st.gguf'}}}}}") == (
        f"models[0] (openai/s): serve.weights {tmp_path / 'st.gguf'} is not a GGUF file (it does not begin with GGUF)"
    )


def test_a_relative_gguf_path_is_the_sweep_folder_s_made_absolute(tmp_path, engines_installed, monkeypatch):
    """The replica runs in another working folder: the plan names the file by its absolute path."""
    from pipeline.serving.engines import serve_plan

    (tmp_path / "m.gguf").write_bytes(b"GGUF" + b"\x00" * 8)
    monkeypatch.chdir(tmp_path)
    spec = spec_of(tmp_path, "{model: openai/s, serve: {engine: llama.cpp, weights: m.gguf}}")
    preflight(spec)
    assert serve_plan(spec.models[0]).weights == str(tmp_path / "m.gguf")


# -- sizes and prices -------------------------------------------------------------------------------
def test_vllm_without_a_gpu_is_refused(tmp_path, engines_installed, hub):
    assert refusal(tmp_path, "{model: openai/x, serve: {engine: vllm, weights: Org/cached, gpus_per_replica: 0}}") == (
        "models[0] (openai/x): serve.gpus_per_replica: vllm needs at least 1 GPU per replica"
    )


def test_a_gpu_hour_price_on_replicas_without_gpus_is_refused(tmp_path):
    assert refusal(tmp_path, "{model: offline/expert, serve: {replicas: 2}, prices: {gpu_hour: 2.5}}") == (
        "models[0] (offline/expert): prices.gpu_hour on replicas without GPUs; price them by replica_hour"
    )


def test_a_served_model_under_a_cap_needs_its_hourly_price(tmp_path):
    assert refusal(tmp_path, "{model: offline/expert, serve: {replicas: 2}}", "run_cap_usd: 5\n") == (
        "models[0] (offline/expert) has a run cap but no price: give prices: {gpu_hour: X} or {replica_hour: X}"
    )
    preflight(spec_of(tmp_path, "{model: offline/expert, serve: {replicas: 2}, prices: {replica_hour: 1}}", "run_cap_usd: 5\n"))


# -- the test double --------------------------------------------------------------------------------
def test_the_test_double_takes_only_a_latency_and_a_batch_size(tmp_path):
    assert refusal(tmp_path, "{model: offline/expert, serve: {engine_args: {max_model_len: 4096}}}") == (
        "models[0] (offline/expert): serve.engine_args: the test double takes only latency_s and max_running, not max_model_len"
    )
    assert refusal(tmp_path, "{model: offline/expert, serve: {engine_args: {latency_s: 61}}}") == (
        "models[0] (offline/expert): serve.engine_args.latency_s must be seconds in [0, 60], got 61"
    )
    assert refusal(tmp_path, "{model: offline/expert, serve: {engine_args: {max_running: -1}}}") == (
        "models[0] (offline/expert): serve.engine_args.max_running must be a whole number >= 0 (0: no limit), got -1"
    )
    preflight(spec_of(tmp_path, "{model: offline/expert, serve: {engine_args: {latency_s: 0.1, max_running: 1}}}"))
    assert refusal(tmp_path, "{model: offline/expert, serve: {weights: Org/cached}}") == (
        "models[0] (offline/expert): serve.weights: the test double serves no weights; leave it out"
    )


# -- the cluster ------------------------------------------------------------------------------------
def test_a_cluster_without_the_gpus_is_refused(tmp_path):
    spec = spec_of(
        tmp_path,
        "{model: openai/a, serve: {engine: vllm, weights: Org/a, replicas: 2, gpus_per_replica: 2}}, "
        "{model: openai/b, serve: {engine: vllm, weights: Org/b}}",
    )
    check_cluster(spec, {"CPU": 16, "GPU": 5}, workers=2)  # 2 x 2 + 1 GPUs: fits
    with pytest.raises(PreflightError) as info:
        check_cluster(spec, {"CPU": 16, "GPU": 4}, workers=2)
    assert str(info.value) == (
        "models[1] (openai/b): serve needs 5 GPUs in all (1 replicas x 1 with the models before it) "
        "but the Ray cluster has 4; nothing was started"
    )
    with pytest.raises(PreflightError) as info:
        check_cluster(spec, {"CPU": 16}, workers=2)
    assert str(info.value) == (
        "models[0] (openai/a): serve needs 4 GPUs in all (2 replicas x 2) but the Ray cluster has 0; nothing was started"
    )


def test_a_cluster_without_the_cpus_is_refused(tmp_path):
    spec = spec_of(tmp_path, "{model: offline/expert, serve: {replicas: 4, cpus_per_replica: 0.5}}")
    check_cluster(spec, {"CPU": 2.1}, workers=2)  # 4 x 0.5 + 2 x 0.05
    with pytest.raises(PreflightError) as info:
        check_cluster(spec, {"CPU": 2}, workers=2)
    assert str(info.value) == (
        "serve: the replicas need 2 CPUs and the 2 episode workers 0.1, but the Ray cluster has 2; nothing was started"
    )


def test_the_cli_refuses_a_served_model_whose_engine_is_missing_in_one_line_and_writes_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(checks, "installed", lambda module: module != "vllm")
    out = tmp_path / "run"
    sweep = tmp_path / "sweep.yaml"
    data = yaml.safe_load(BASE.format(out=out))
    data["models"] = [{"model": "openai/qwen", "serve": {"engine": "vllm", "weights": "Qwen/Qwen2.5-7B-Instruct"}}]
    sweep.write_text(yaml.safe_dump(data))
    assert main(["run", str(sweep), "--progress", "off"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"{sweep}: models[0] (openai/qwen): serve.engine vllm is not installed here (no module vllm; pip install 'ray[llm]' vllm)"
    ] or (
        len(err) == 1 and err[0].endswith("serve.engine vllm is not installed here (no module vllm; pip install 'ray[llm]' vllm)")
    )
    assert not out.exists()


# -- the section's shape ----------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("model", "message"),
    [
        (
            "{model: openai/q, serve: {weights: Org/q}}",
            "models[0]: serve.engine: name the engine (vllm, sglang, llama.cpp, test-double)",
        ),
        (
            "{model: openai/q, serve: {engine: vllm}}",
            "models[0]: serve.weights: give the weights vllm serves (a hub id or a local path)",
        ),
        (
            "{model: offline/expert, serve: {engine: vllm, weights: Org/q}}",
            "models[0]: serve.engine vllm serves open weights; 'offline/expert' is a test double (engine: test-double)",
        ),
        (
            "{model: offline/replay, api_base: /r, serve: {}}",
            "models[0]: serve: the sweep serves this model itself; leave api_base out",
        ),
        (
            "{model: offline/replay, serve: {}}",
            "models[0]: serve.engine test-double serves offline/expert or offline/random, not 'offline/replay'",
        ),
        (
            "{model: offline/expert, serve: {engine: tgi}}",
            "models[0].serve.engine: Input should be 'vllm', 'sglang', 'llama.cpp' or 'test-double'",
        ),
        ("{model: offline/expert, serve: {replicas: 0}}", "models[0].serve.replicas: 0 is out of range [1, 256]"),
        ("{model: offline/expert, serve: {replica: 2}}", "models[0].serve.replica: unknown field"),
        (
            "{model: offline/expert, serve: {}, prices: {input: 1, output: 2}}",
            "models[0]: a served model is priced by the hour: prices: {gpu_hour: X} or {replica_hour: X}",
        ),
        (
            "{model: offline/expert, prices: {gpu_hour: 1}}",
            "models[0]: prices.gpu_hour / replica_hour are for a model the sweep serves (give serve:)",
        ),
        (
            "{model: offline/expert, serve: {}, prices: {gpu_hour: 1, replica_hour: 1}}",
            "models[0].prices: give gpu_hour or replica_hour, not both",
        ),
        (
            "{model: offline/expert, prices: {input: 1}}",
            "models[0].prices: give input and output (USD per million tokens), or gpu_hour / replica_hour for a served model",
        ),
    ],
)
def test_the_serve_section_is_checked_in_one_line(tmp_path, model, message):
    with pytest.raises(SpecError) as info:
        spec_of(tmp_path, model)
    assert str(info.value) == f"sweep.yaml: {message}"


def test_vllm_gets_automatic_prefix_caching_cached_token_reports_and_its_tensor_parallel_degree_unless_the_sweep_sets_them():
    from pipeline.serving.engines import engine_kwargs, llm_config, serve_plan

    def plan(serve: str, model: str = "openai/Qwen/Qwen2.5-7B-Instruct"):
        spec = parse_spec(
            f"run: r\noutput: /tmp/x\nmodels:\n  - model: {model}\n"
            f"    serve: {serve}\nmethods: [{{method: react}}]\nenvironments: [{{benchmark: blocksworld, tasks: ['3']}}]\n",
            "sweep.yaml",
        )
        return serve_plan(spec.models[0])

    def kwargs(serve: str) -> dict:
        return engine_kwargs(plan(serve))

    # vLLM reports usage.prompt_tokens_details.cached_tokens only with enable_prompt_tokens_details
    assert kwargs("{engine: vllm, weights: Qwen/Qwen2.5-7B-Instruct, gpus_per_replica: 2}") == {
        "tensor_parallel_size": 2,
        "enable_prefix_caching": True,
        "enable_prompt_tokens_details": True,
    }
    assert kwargs(
        "{engine: vllm, weights: Qwen/Qwen2.5-7B-Instruct, engine_args: {enable_prefix_caching: false, max_model_len: 8192}}"
    ) == {"tensor_parallel_size": 1, "enable_prefix_caching": False, "enable_prompt_tokens_details": True, "max_model_len": 8192}
    assert kwargs("{engine: vllm, weights: Qwen/Qwen2.5-7B-Instruct, engine_args: {enable_prompt_tokens_details: false}}") == {
        "tensor_parallel_size": 1,
        "enable_prefix_caching": True,
        "enable_prompt_tokens_details": False,
    }
    # the LLMConfig the service deploys carries it (ray.serve.llm hands it to vLLM's server state)
    assert llm_config(plan("{engine: vllm, weights: Qwen/Qwen2.5-7B-Instruct, replicas: 2, max_in_flight: 8}")) == {
        "model_loading_config": {"model_id": "Qwen/Qwen2.5-7B-Instruct", "model_source": "Qwen/Qwen2.5-7B-Instruct"},
        "deployment_config": {"num_replicas": 2, "max_ongoing_requests": 8},
        "engine_kwargs": {"tensor_parallel_size": 1, "enable_prefix_caching": True, "enable_prompt_tokens_details": True},
    }
    # a vLLM frontend flag: SGLang's engine is not given it
    sglang = llm_config(plan("{engine: sglang, weights: Qwen/Qwen2.5-7B-Instruct}"))
    assert sglang["llm_engine"] == "SGLang" and "enable_prompt_tokens_details" not in sglang["engine_kwargs"]


def test_each_engine_names_where_the_gateway_reads_its_replicas_queue():
    from pipeline.serving.engines import serve_plan
    from pipeline.serving.service import queue_source
    from workers.llm.providers import QueueSource

    def source(model: str, serve: str) -> QueueSource:
        spec = parse_spec(
            f"run: r\noutput: /tmp/x\nmodels:\n  - model: {model}\n    serve: {serve}\n"
            "methods: [{method: react}]\nenvironments: [{benchmark: blocksworld, tasks: ['3']}]\n",
            "sweep.yaml",
        )
        return queue_source(serve_plan(spec.models[0]), "recap-r-0")

    assert source("offline/expert", "{replicas: 2}") == QueueSource(
        kind="replica_metrics", app="recap-r-0", gauges=("vllm:num_requests_waiting", "ray_vllm_num_requests_waiting")
    )
    assert source("openai/smollm2", "{engine: llama.cpp, weights: /w/smollm2.gguf}") == QueueSource(
        kind="replica_ongoing", app="recap-r-0", running=1
    )
    assert source("openai/Qwen/Qwen2.5-7B-Instruct", "{engine: vllm, weights: Qwen/Qwen2.5-7B-Instruct}") == QueueSource(
        kind="ray_metrics",
        app="recap-r-0",
        gauges=("vllm:num_requests_waiting", "ray_vllm_num_requests_waiting"),
        labels={"model_name": "Qwen/Qwen2.5-7B-Instruct"},
    )
    assert source("openai/Qwen/Qwen2.5-7B-Instruct", "{engine: sglang, weights: Qwen/Qwen2.5-7B-Instruct}") == QueueSource(
        kind="ray_metrics",
        app="recap-r-0",
        gauges=("sglang:num_queue_reqs", "ray_sglang_num_queue_reqs"),
        labels={"model_name": "Qwen/Qwen2.5-7B-Instruct"},
    )
