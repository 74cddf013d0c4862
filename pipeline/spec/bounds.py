"""The sweep file's documented bounds: sizes, lengths and the range of every number field, in one table.

Kept apart from the schema so that the refusal of a number out of range, the tests that check
every number field has a range (tests/pipeline/test_spec_bounds.py) and the README read the same
figures.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pydantic import GetCoreSchemaHandler
from pydantic_core import core_schema

from schemas.ranges import number_text

MAX_SPEC_BYTES = 1 << 20
MAX_SCALAR_CHARS = 4096
MAX_DEPTH = 16
INT64_MAX = 2**63 - 1
SEED_MAX = 2**31 - 1
NAME_MAX = 200
LONG_MAX = 2000
SELECTOR_MAX = 1000
PATH_MAX = 4096
USD_MAX = 1_000_000.0
PRICE_MAX = 10_000.0
STEP_MULTIPLIER_MIN = 0.1
STEP_MULTIPLIER_MAX = 1000.0
WORKERS_MAX = 1024
ATTEMPTS_MAX = 100
RPM_MAX = 10**7
TPM_MAX = 10**11
CONCURRENCY_MAX = 10_000
#: gateway actors per model (each a process: a few suffice for a 10K-RPM quota)
GATEWAY_SHARDS_MAX = 64
RETRIES_MAX = 100
SECONDS_MAX = 86_400.0
#: the shortest quota window and attempt timeout: below it a quota or a timeout means nothing
SECONDS_MIN = 0.1
#: an attempt's timeout: every attempt of a call must fit in the gateway's total timeout per
#: call (``DeploymentConfig.total_timeout_s``, 900 s); a longer one would be cut there silently
TIMEOUT_MAX = 900.0
#: the smallest per-episode dollar limit (one micro-dollar: prices have at most 6 decimals)
EPISODE_USD_MIN = 1e-6
LLM_CALLS_MAX = 10**6
TOKENS_MAX = 10**10
LIMIT_MAX = 100_000
NUM_CPUS_MAX = 4096
OBJECT_STORE_MB_MIN = 64
OBJECT_STORE_MB_MAX = 1 << 20
#: Ray books fractional CPUs in steps of 0.0001; below a thousandth a share is meaningless
WORKER_CPUS_MIN = 0.001
WORKER_CPUS_MAX = 1024.0
LIST_MAX = 100
#: served models (models[].serve): replicas of one model, GPUs of one replica (tensor parallel)
SERVE_REPLICAS_MAX = 256
SERVE_GPUS_MAX = 64
#: output tokens per second of one replica
SERVE_TOKENS_PER_S_MAX = 1e7
SAMPLING_SEEDS_MAX = 10_000
SELECTORS_MAX = 1000
INSTANCES_MAX = 10_000
INSTANCES_TOTAL_MAX = 20_000


@dataclass(frozen=True)
class Bound:
    """The sane range of one number field of the sweep file: ``lo <= value <= hi``."""

    lo: float
    hi: float

    def text(self) -> str:
        """``[lo, hi]`` as the refusal shows it."""
        return f"[{number_text(self.lo)}, {number_text(self.hi)}]"


#: Every number field of the sweep file and its range, in one place: the ``Bounded(path)`` in a
#: field's type looks its range up here, and a value outside is refused in one line that says
#: the range (``models[0].window_s: 1e-300 is out of range [0.1, 86400]``). A number field
#: without an entry fails tests/pipeline/test_spec_bounds.py. The free-form mappings have their
#: own tables: ``params`` (:data:`workers.llm.providers.NUMERIC_PARAMS`), ``options`` of a test
#: double (:class:`workers.llm.offline.knobs.Knobs`), method ``settings`` (the method's config).
NUMBER_BOUNDS: dict[str, Bound] = {
    "models[].rpm": Bound(1, RPM_MAX),
    "models[].tpm": Bound(1, TPM_MAX),
    "models[].concurrency": Bound(1, CONCURRENCY_MAX),
    "models[].window_s": Bound(SECONDS_MIN, SECONDS_MAX),
    "models[].retries": Bound(0, RETRIES_MAX),
    "models[].timeout_s": Bound(SECONDS_MIN, TIMEOUT_MAX),
    "models[].max_usage_rejections": Bound(1, 1000),
    "models[].gateway_shards": Bound(1, GATEWAY_SHARDS_MAX),
    "models[].prices.input": Bound(0, PRICE_MAX),
    "models[].prices.output": Bound(0, PRICE_MAX),
    "models[].prices.cached_input": Bound(0, PRICE_MAX),
    "models[].prices.cache_write": Bound(0, PRICE_MAX),
    "models[].cap_usd": Bound(0, USD_MAX),
    "models[].prices.gpu_hour": Bound(0, PRICE_MAX),
    "models[].prices.replica_hour": Bound(0, PRICE_MAX),
    "models[].serve.replicas": Bound(1, SERVE_REPLICAS_MAX),
    "models[].serve.gpus_per_replica": Bound(0, SERVE_GPUS_MAX),
    "models[].serve.cpus_per_replica": Bound(WORKER_CPUS_MIN, WORKER_CPUS_MAX),
    "models[].serve.max_in_flight": Bound(1, CONCURRENCY_MAX),
    "models[].serve.ready_timeout_s": Bound(1, SECONDS_MAX),
    "models[].serve.tokens_per_s": Bound(0.001, SERVE_TOKENS_PER_S_MAX),
    "environments[].limit": Bound(1, LIMIT_MAX),
    "limits.llm_calls": Bound(1, LLM_CALLS_MAX),
    "limits.tokens": Bound(1, TOKENS_MAX),
    "limits.usd": Bound(EPISODE_USD_MIN, USD_MAX),
    "ray.num_cpus": Bound(1, NUM_CPUS_MAX),
    "ray.object_store_mb": Bound(OBJECT_STORE_MB_MIN, OBJECT_STORE_MB_MAX),
    "ray.worker_cpus": Bound(WORKER_CPUS_MIN, WORKER_CPUS_MAX),
    "ray.sandboxes_per_node": Bound(1, WORKERS_MAX),
    "ray.episodes_per_process": Bound(1, WORKERS_MAX),
    "sampling_seeds[]": Bound(0, SEED_MAX),
    "step_multiplier": Bound(STEP_MULTIPLIER_MIN, STEP_MULTIPLIER_MAX),
    "methods[].step_multiplier": Bound(STEP_MULTIPLIER_MIN, STEP_MULTIPLIER_MAX),
    "methods[].step_multipliers{}": Bound(STEP_MULTIPLIER_MIN, STEP_MULTIPLIER_MAX),
    "run_cap_usd": Bound(0, USD_MAX),
    "workers": Bound(1, WORKERS_MAX),
    "max_attempts": Bound(1, ATTEMPTS_MAX),
}


@dataclass(frozen=True)
class Bounded:
    """The range check of a number field, found by its path in :data:`NUMBER_BOUNDS` (put in the
    field's ``Annotated`` type, after the int/float check)."""

    path: str

    def __post_init__(self) -> None:
        if self.path not in NUMBER_BOUNDS:
            raise KeyError(f"{self.path} has no entry in NUMBER_BOUNDS")

    @property
    def bound(self) -> Bound:
        """This field's range."""
        return NUMBER_BOUNDS[self.path]

    def check(self, v: float) -> float:
        """``v`` unchanged, or a ValueError that names the range."""
        b = self.bound
        if not b.lo <= v <= b.hi:
            raise ValueError(f"{number_text(v)} is out of range {b.text()}")
        return v

    def __get_pydantic_core_schema__(self, source: Any, handler: GetCoreSchemaHandler) -> core_schema.CoreSchema:
        return core_schema.no_info_after_validator_function(self.check, handler(source))
