"""The Ray Serve application of each serving engine, and what a served model needs of the cluster.

- ``test-double``: :func:`workers.serving.test_double.deployment` (no weights, no GPU);
- ``llama.cpp``: :func:`workers.serving.llama_cpp.deployment` (a GGUF file, ``llama_cpp.server``);
- ``vllm`` / ``sglang``: ``ray.serve.llm.build_openai_app`` with one ``LLMConfig`` (the model id
  is what the sweep's ``openai/<id>`` names; weights, replicas, tensor parallel degree and the
  engine arguments passed through; vLLM's automatic prefix caching on, and the cached prompt
  tokens reported in its replies, unless the engine arguments say otherwise: ReCAP re-sends
  long prefixes).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

from pipeline.spec import OFFLINE_PREFIX, ModelSpec

#: the engines whose replicas' queue is read from Ray's metrics (:mod:`workers.serving.queue_source`,
#: ``ray_metrics``): a local cluster serving one collects metrics (:func:`pipeline.raysetup.needs_metrics`)
METRICS_ENGINES = ("vllm", "sglang")


@dataclass(frozen=True)
class ServePlan:
    """One served model as the service deploys it."""

    label: str
    engine: str
    model: str
    weights: str | None
    replicas: int
    gpus: int
    cpus: float
    max_in_flight: int
    ready_timeout_s: float
    engine_args: dict[str, Any]
    #: USD per replica-hour (gpu_hour x GPUs, or replica_hour); 0 when the sweep gives no price
    usd_per_replica_hour: float

    @property
    def served_name(self) -> str:
        """The model id the server answers to (``openai/<id>`` in the sweep; the test double's own)."""
        return self.model.split("/", 1)[1] if "/" in self.model else self.model

    @property
    def concurrency(self) -> int:
        """Calls the gateway keeps outstanding: every replica's share."""
        return self.replicas * self.max_in_flight


def serve_plan(m: ModelSpec) -> ServePlan:
    """The deployment of sweep entry ``m`` (which has ``serve``)."""
    assert m.serve is not None
    s = m.serve
    engine = s.engine_for(m.model, OFFLINE_PREFIX)
    gpus = s.gpus(engine)
    per_hour = 0.0
    if m.prices is not None and m.prices.gpu_hour is not None:
        per_hour = m.prices.gpu_hour * gpus
    elif m.prices is not None and m.prices.replica_hour is not None:
        per_hour = m.prices.replica_hour
    weights = s.weights
    if engine == "llama.cpp" and weights is not None:
        # a local file, read by a replica whose working folder is not the sweep's
        weights = os.path.abspath(os.path.expanduser(weights))
    return ServePlan(
        label=m.name,
        engine=engine,
        model=m.model,
        weights=weights,
        replicas=s.replicas,
        gpus=gpus,
        cpus=s.cpus(engine),
        max_in_flight=s.max_in_flight,
        ready_timeout_s=s.ready_timeout_s,
        engine_args=dict(s.engine_args),
        usd_per_replica_hour=per_hour,
    )


def application(plan: ServePlan, deployment_name: str) -> Any:
    """The bound Serve application of ``plan`` (``serve.run`` deploys it)."""
    if plan.engine == "test-double":
        from workers.serving import test_double  # lazy: Serve loads only where a sweep serves a model

        return test_double.deployment(
            plan.model,
            plan.engine_args,
            name=deployment_name,
            replicas=plan.replicas,
            max_in_flight=plan.max_in_flight,
            cpus=plan.cpus,
        )
    if plan.engine == "llama.cpp":
        from workers.serving import llama_cpp  # lazy: as above

        assert plan.weights is not None
        return llama_cpp.deployment(
            plan.served_name,
            plan.weights,
            plan.engine_args,
            name=deployment_name,
            replicas=plan.replicas,
            max_in_flight=plan.max_in_flight,
            cpus=plan.cpus,
            gpus=plan.gpus,
        )
    return _llm_application(plan)


def engine_kwargs(plan: ServePlan) -> dict[str, Any]:
    """vLLM's / SGLang's engine arguments: the tensor parallel degree of a replica's GPUs and
    automatic prefix caching on (ReCAP re-sends long prefixes: the pinned demonstration and task,
    the window), each unless the sweep's ``engine_args`` set it; the rest passed as they are.
    The server reports the prompt tokens it read from the cache as
    ``usage.prompt_tokens_details.cached_tokens``, which the gateway records in
    ``llm_calls.cached_prompt_tokens`` like a provider's cache hits (workers.llm.calling).

    vLLM reports them only when asked: ``enable_prompt_tokens_details`` (``--enable-prompt-tokens-details``,
    a field of vLLM's ``FrontendArgs`` in ``vllm/entrypoints/openai/cli_args.py``, default False:
    "If set to True, enable prompt_tokens_details in usage"), so it is on for vLLM unless the sweep
    says otherwise. ``ray.serve.llm`` hands the engine arguments that are ``FrontendArgs`` fields to
    vLLM's server state (``ray/llm/_internal/serve/engines/vllm/vllm_models.py:211-229``,
    ``vllm_engine.py:433``, Ray 2.60)."""
    defaults: dict[str, Any] = {"tensor_parallel_size": plan.gpus, "enable_prefix_caching": True}
    if plan.engine == "vllm":
        defaults["enable_prompt_tokens_details"] = True
    return {**defaults, **plan.engine_args}


def llm_config(plan: ServePlan) -> dict[str, Any]:
    """The ``ray.serve.llm.LLMConfig`` fields of a vLLM / SGLang ``plan`` (what the service deploys)."""
    config: dict[str, Any] = {
        "model_loading_config": {"model_id": plan.served_name, "model_source": plan.weights},
        "deployment_config": {
            "num_replicas": plan.replicas,
            "max_ongoing_requests": plan.max_in_flight,
        },
        "engine_kwargs": engine_kwargs(plan),
    }
    if plan.engine == "sglang":
        config["llm_engine"] = "SGLang"
    return config


def _llm_application(plan: ServePlan) -> Any:
    """vLLM / SGLang through ``ray.serve.llm`` (only where it is installed: preflight refuses otherwise)."""
    from ray.serve.llm import LLMConfig, build_openai_app  # lazy: Ray's LLM serving needs vLLM

    return build_openai_app({"llm_configs": [LLMConfig(**llm_config(plan))]})
