"""The sweep file: one YAML document that says what to run, where to write it and what it may cost.

This package is its public face: ``from pipeline.spec import parse_spec, SweepSpec, ...``. Its
parts, one job each: :mod:`~pipeline.spec.bounds` (the documented sizes and number ranges),
:mod:`~pipeline.spec.fields` (checked field types), :mod:`~pipeline.spec.schema` (the pydantic
models), :mod:`~pipeline.spec.safe_yaml` (the hardened file and YAML reader),
:mod:`~pipeline.spec.load` (text to a validated spec, one line per problem) and
:mod:`~pipeline.spec.reach` (the object-store and Ray-address reachability probes).

Example::

    run: demo                         # run name (letters, digits, . _ -)
    output: runs/demo                 # local folder, or an object-store URI (s3://bucket/prefix)
    models:
      - model: offline/expert         # a litellm model string
        options: {invalid_action_rate: 0.1}   # test-double knobs (part of the unit hash)
        params: {max_tokens: 512}     # generation params (part of the unit hash)
        rpm: 600                      # transport settings: not part of the unit hash
        prices: {input: 2.5, output: 10, cached_input: 1.25}   # USD per million tokens (+ cache_write)
        cap_usd: 2.0                  # per-model dollar cap
    methods:
      - method: recap
        profile: paper
        ablation: no_think
        settings: {window: 64}
      - method: react
        step_multiplier: 4            # this method's step cap (default: the sweep's)
        step_multipliers: {robotouille/synchronous/2: 3}   # per task: <benchmark>/<task selector>
    environments:
      - benchmark: robotouille
        tasks: [synchronous/6, asynchronous]   # selectors given to the benchmark
        limit: 2                              # first N instances per selector
        options: {data_dir: ~/robotouille}    # the benchmark's declared options only (others are refused);
                                              # those that change what an episode does are in the unit id
      - benchmark: blocksworld
        instances: [blocksworld/3@1]
    sampling_seeds: [0]               # each sampling seed is its own unit (old name: seeds)
    step_multiplier: 4
    limits: {llm_calls: 200, tokens: 2000000, usd: 1.0}     # per episode
    run_cap_usd: 5.0
    workers: 8
    max_attempts: 3
    order: interleaved                # start order: interleaved (default; balanced under a cap) or plan

Hardening (every rule fails as one line before any model call or write):

* The file: a regular file of at most :data:`MAX_SPEC_BYTES` (1 MiB) of UTF-8 text (devices,
  FIFOs and sockets are refused before they are opened for reading). YAML anchors, aliases and
  merge keys (``&a``, ``*a``, ``<<``) are refused (an alias bomb cannot expand), so is a key
  given twice in one mapping at any depth (``duplicate key 'cap_usd' at line 12``), a value
  longer than :data:`MAX_SCALAR_CHARS` characters and nesting deeper than :data:`MAX_DEPTH`.
* Numbers, anywhere in the file (free-form ``params``/``options``/``settings`` included):
  floats must be finite (``.nan``/``.inf`` refused), integers must fit a signed 64-bit column.
  Every number field refuses ``true``/``false`` and has a sane range, declared in one table
  (:data:`NUMBER_BOUNDS`) and said in the refusal (``models[0].window_s: 1e-300 is out of range
  [0.1, 86400]``): sampling_seeds 0..2**31-1, workers 1..1024, max_attempts 1..100, rpm 1..10**7,
  tpm 1..10**11, concurrency 1..10000, retries 0..100, window_s 0.1 s..a day, timeout_s 0.1..900 s
  (the gateway's total time per call), max_usage_rejections 1..1000, limits.llm_calls 1..10**6, limits.tokens 1..10**10,
  limits.usd 10**-6..10**6, environment limit 1..10**5, ray.num_cpus 1..4096,
  ray.object_store_mb 64..1048576, ray.worker_cpus 0.001..1024, ray.episodes_per_process 1..1024; caps 0..10**6 USD, prices
  0..10**4 USD per million tokens, step_multiplier 0.1..1000 (the sweep's, a method's and
  each value of a method's step_multipliers). Generation ``params`` have theirs
  in :data:`workers.llm.providers.NUMERIC_PARAMS` (max_tokens 1..262144 and at most the model's
  own output limit: :func:`pipeline.preflight.check_models`).
* ``api_key_env`` names a credential: a variable ending in ``_KEY``, ``_TOKEN``, ``_SECRET``,
  ``_PASSWORD`` (...) or one the provider itself reads; any other name (``HOME``) needs
  ``api_key_env_is_credential: true`` (:func:`pipeline.preflight.check_models`).
* Strings: run names match ``[A-Za-z0-9][A-Za-z0-9_.-]*`` (at most 200 characters); labels are
  at most 200 characters of letters, digits, space and ``- _ . : @ + / ( ) , = # %`` (no
  brackets, backslashes or control characters: nothing a terminal or Rich markup interprets);
  model strings are at most 2000 printable ASCII characters without spaces, brackets or
  backslashes; api_base at most 2000 characters; every other name at most 200 and selectors or
  instance ids at most 1000 printable characters.
* Sizes: at most 100 models, methods and environments, 10000 sampling seeds, 1000 task selectors and
  10000 instance ids per environment (20000 in all).
* Paths: ``output`` is resolved once, here (``~`` expanded, made absolute), so every component
  sees the same folder; so are ``environments[].options`` paths (``data_dir`` and every
  ``*_dir`` option) and an offline/replay model's ``api_base`` folder. An object-store output
  must use a known scheme; :func:`check_output_location` checks that it can be reached before
  anything is written.
* ``ray.address``: ``auto``, ``local``, ``host:port`` or ``ray://host:port`` (port 1..65535).
"""

from __future__ import annotations

from pipeline.spec.bounds import (
    ATTEMPTS_MAX,
    CONCURRENCY_MAX,
    EPISODE_USD_MIN,
    INSTANCES_MAX,
    INSTANCES_TOTAL_MAX,
    INT64_MAX,
    LIMIT_MAX,
    LIST_MAX,
    LLM_CALLS_MAX,
    LONG_MAX,
    MAX_DEPTH,
    MAX_SCALAR_CHARS,
    MAX_SPEC_BYTES,
    NAME_MAX,
    NUM_CPUS_MAX,
    NUMBER_BOUNDS,
    OBJECT_STORE_MB_MAX,
    OBJECT_STORE_MB_MIN,
    PATH_MAX,
    PRICE_MAX,
    RETRIES_MAX,
    RPM_MAX,
    SAMPLING_SEEDS_MAX,
    SECONDS_MAX,
    SECONDS_MIN,
    SEED_MAX,
    SELECTOR_MAX,
    SELECTORS_MAX,
    STEP_MULTIPLIER_MAX,
    STEP_MULTIPLIER_MIN,
    TIMEOUT_MAX,
    TOKENS_MAX,
    TPM_MAX,
    USD_MAX,
    WORKER_CPUS_MAX,
    WORKER_CPUS_MIN,
    WORKERS_MAX,
    Bound,
    Bounded,
)
from pipeline.spec.fields import (
    CREDENTIAL_WORDS,
    OFFLINE_PREFIX,
    URI_SCHEMES,
    Label,
    Name,
    Selector,
    check_ray_address,
    credential_name,
)
from pipeline.spec.load import load_spec, parse_spec, text_hash, with_overrides
from pipeline.spec.reach import STORE_CHECK_TIMEOUT_S, check_output_location, check_ray_address_reachable
from pipeline.spec.safe_yaml import load_yaml, read_spec_text
from pipeline.spec.schema import (
    DEPLOYMENT_FIELDS,
    SPEC_ONLY_FIELDS,
    EnvSpec,
    LimitsSpec,
    MethodSpec,
    ModelSpec,
    PriceSpec,
    RaySpec,
    SweepSpec,
)
from schemas.ranges import number_text

__all__ = [
    "ATTEMPTS_MAX",
    "Bound",
    "Bounded",
    "CONCURRENCY_MAX",
    "CREDENTIAL_WORDS",
    "DEPLOYMENT_FIELDS",
    "EPISODE_USD_MIN",
    "EnvSpec",
    "INSTANCES_MAX",
    "INSTANCES_TOTAL_MAX",
    "INT64_MAX",
    "LIMIT_MAX",
    "LIST_MAX",
    "LLM_CALLS_MAX",
    "LONG_MAX",
    "Label",
    "LimitsSpec",
    "MAX_DEPTH",
    "MAX_SCALAR_CHARS",
    "MAX_SPEC_BYTES",
    "MethodSpec",
    "ModelSpec",
    "NAME_MAX",
    "NUMBER_BOUNDS",
    "NUM_CPUS_MAX",
    "Name",
    "OBJECT_STORE_MB_MAX",
    "OBJECT_STORE_MB_MIN",
    "OFFLINE_PREFIX",
    "PATH_MAX",
    "PRICE_MAX",
    "PriceSpec",
    "RETRIES_MAX",
    "RPM_MAX",
    "RaySpec",
    "SECONDS_MAX",
    "SECONDS_MIN",
    "SAMPLING_SEEDS_MAX",
    "SEED_MAX",
    "SELECTORS_MAX",
    "SELECTOR_MAX",
    "SPEC_ONLY_FIELDS",
    "STEP_MULTIPLIER_MAX",
    "STEP_MULTIPLIER_MIN",
    "STORE_CHECK_TIMEOUT_S",
    "Selector",
    "SweepSpec",
    "TIMEOUT_MAX",
    "TOKENS_MAX",
    "TPM_MAX",
    "URI_SCHEMES",
    "USD_MAX",
    "WORKERS_MAX",
    "WORKER_CPUS_MAX",
    "WORKER_CPUS_MIN",
    "check_output_location",
    "check_ray_address",
    "check_ray_address_reachable",
    "credential_name",
    "load_spec",
    "load_yaml",
    "number_text",
    "parse_spec",
    "read_spec_text",
    "text_hash",
    "with_overrides",
]
