"""The ``models[].serve`` section: an open-weight model the sweep deploys on its Ray cluster itself.

Why a section of the model entry: today a self-hosted model is served by hand and named by
``api_base``, so the sweep knows nothing of its replicas, GPUs or cost. With ``serve:`` the
sweep starts the model as a run service (Ray Serve, :mod:`pipeline.serving`), points the
gateway at its route, keeps ``replicas x max_in_flight`` calls outstanding and charges the
replica-hours held to the run's ledger (``prices: {gpu_hour: X}`` or ``{replica_hour: X}``).

Engines: ``vllm`` and ``sglang`` (``ray.serve.llm``), ``llama.cpp`` (a Serve deployment around
``llama_cpp.server`` for GGUF weights) and ``test-double`` (a Serve deployment answering like
the ``offline/`` test doubles, so the whole path is tested without weights or a GPU). What can
only be told on the machine (engine installed, weights present, GPUs in the cluster) is checked
in preflight (:mod:`pipeline.serving.checks`); this module checks the shape of the section.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import AfterValidator, Field, field_validator

from pipeline.spec.bounds import LONG_MAX, Bounded
from pipeline.spec.fields import NOT_BOOL, StrictModel, check_free_form, printable

#: the engines a served model can run on; ``test-double`` is labelled as one everywhere
ENGINES = ("vllm", "sglang", "llama.cpp", "test-double")
Engine = Literal["vllm", "sglang", "llama.cpp", "test-double"]
TEST_DOUBLE_ENGINE = "test-double"
#: GPUs a replica of each engine asks for unless ``gpus_per_replica`` says otherwise
DEFAULT_GPUS = {"vllm": 1, "sglang": 1, "llama.cpp": 0, "test-double": 0}
#: CPUs a replica asks for unless ``cpus_per_replica`` says otherwise
DEFAULT_CPUS = {"vllm": 1.0, "sglang": 1.0, "llama.cpp": 1.0, "test-double": 0.05}


class ServeSpec(StrictModel):
    """``models[].serve``: which engine serves which weights, how many replicas of what size,
    how many requests each replica takes at once, and the engine's own arguments."""

    #: None: ``test-double`` for an ``offline/`` model; a real model must name its engine
    engine: Engine | None = None
    #: a hub id (``Qwen/Qwen2.5-7B-Instruct``) or a local path (a GGUF file for llama.cpp)
    weights: Annotated[str, Field(min_length=1, max_length=LONG_MAX), AfterValidator(printable)] | None = None
    replicas: Annotated[int, NOT_BOOL, Bounded("models[].serve.replicas")] = 1
    #: GPUs of one replica (tensor parallel degree for vLLM/SGLang); None: the engine's default
    gpus_per_replica: Annotated[int, NOT_BOOL, Bounded("models[].serve.gpus_per_replica")] | None = None
    cpus_per_replica: Annotated[float, NOT_BOOL, Bounded("models[].serve.cpus_per_replica")] | None = None
    #: requests one replica takes at once; the gateway keeps replicas x max_in_flight outstanding
    max_in_flight: Annotated[int, NOT_BOOL, Bounded("models[].serve.max_in_flight")] = 8
    #: seconds the sweep waits for every replica to answer its health request
    ready_timeout_s: Annotated[float, NOT_BOOL, Bounded("models[].serve.ready_timeout_s")] = 900.0
    #: output tokens per second of one replica holding its max_in_flight calls: what ``recap
    #: estimate`` prices the replica-hours by (None: ``recap estimate --probe`` measures it)
    tokens_per_s: Annotated[float, NOT_BOOL, Bounded("models[].serve.tokens_per_s")] | None = None
    #: passed to the engine as they are (vLLM's engine_kwargs, llama.cpp server settings)
    engine_args: dict[str, Any] = Field(default_factory=dict)

    @field_validator("engine_args")
    @classmethod
    def _engine_args(cls, v: dict[str, Any]) -> dict[str, Any]:
        return check_free_form(v, "engine_args")

    def engine_for(self, model: str, offline_prefix: str) -> str:
        """The engine that serves ``model``: the one named, else the test double for ``offline/``."""
        if self.engine is not None:
            return self.engine
        return TEST_DOUBLE_ENGINE if model.startswith(offline_prefix) else ""

    def gpus(self, engine: str) -> int:
        return self.gpus_per_replica if self.gpus_per_replica is not None else DEFAULT_GPUS.get(engine, 0)

    def cpus(self, engine: str) -> float:
        return self.cpus_per_replica if self.cpus_per_replica is not None else DEFAULT_CPUS.get(engine, 1.0)
