"""The sweep file: one YAML document that says what to run, where to write it and what it may cost.

Why pydantic: every field is checked before anything runs, unknown keys are errors (a typo such
as ``rmp:`` must not silently drop a rate limit), and the first problem is reported as one line
naming the file and the field (``sweep.yaml: models[0].rpm: must be > 0``).

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
      - benchmark: blocksworld
        instances: [blocksworld/3@1]
    seeds: [0]
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
  [0.1, 86400]``): seeds 0..2**31-1, workers 1..1024, max_attempts 1..100, rpm 1..10**7,
  tpm 1..10**11, concurrency 1..10000, retries 0..100, window_s 0.1 s..a day, timeout_s 0.1..900 s
  (the gateway's total time per call), max_usage_rejections 1..1000, limits.llm_calls 1..10**6, limits.tokens 1..10**10,
  limits.usd 10**-6..10**6, environment limit 1..10**5, ray.num_cpus 1..4096,
  ray.object_store_mb 64..1048576, ray.worker_cpus 0.001..1024; caps 0..10**6 USD, prices
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
* Sizes: at most 100 models, methods and environments, 10000 seeds, 1000 task selectors and
  10000 instance ids per environment (20000 in all).
* Paths: ``output`` is resolved once, here (``~`` expanded, made absolute), so every component
  sees the same folder; so are ``environments[].options`` paths (``data_dir`` and every
  ``*_dir`` option) and an offline/replay model's ``api_base`` folder. An object-store output
  must use a known scheme; :func:`check_output_location` checks that it can be reached before
  anything is written.
* ``ray.address``: ``auto``, ``local``, ``host:port`` or ``ray://host:port`` (port 1..65535).
"""

from __future__ import annotations

import hashlib
import ipaddress
import math
import os
import re
import stat
import unicodedata
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    GetCoreSchemaHandler,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)
from pydantic_core import core_schema

from pipeline.errors import SpecError
from schemas.ranges import number_text

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]*$")
#: labels (models, methods): what is printed in tables and unit keys
_LABEL = re.compile(r"^[A-Za-z0-9 _.:@+/(),=#%\-]+$")
#: litellm model strings: printable ASCII without space, brackets or backslash
_MODEL = re.compile(r"^[\x21-\x5a\x5e-\x7e]+$")
_ENV_VAR = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")

#: models served in-process by the gateway's test-double provider (no key, no real spend)
OFFLINE_PREFIX = "offline/"

# -- documented bounds ---------------------------------------------------------------------------
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
SEEDS_MAX = 10_000
SELECTORS_MAX = 1000
INSTANCES_MAX = 10_000
INSTANCES_TOTAL_MAX = 20_000

#: object-store schemes an output may use (``file://`` is a local folder)
URI_SCHEMES = ("file", "s3", "gs", "gcs", "hdfs", "abfs", "abfss")


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
    "models[].prices.input": Bound(0, PRICE_MAX),
    "models[].prices.output": Bound(0, PRICE_MAX),
    "models[].prices.cached_input": Bound(0, PRICE_MAX),
    "models[].prices.cache_write": Bound(0, PRICE_MAX),
    "models[].cap_usd": Bound(0, USD_MAX),
    "environments[].limit": Bound(1, LIMIT_MAX),
    "limits.llm_calls": Bound(1, LLM_CALLS_MAX),
    "limits.tokens": Bound(1, TOKENS_MAX),
    "limits.usd": Bound(EPISODE_USD_MIN, USD_MAX),
    "ray.num_cpus": Bound(1, NUM_CPUS_MAX),
    "ray.object_store_mb": Bound(OBJECT_STORE_MB_MIN, OBJECT_STORE_MB_MAX),
    "ray.worker_cpus": Bound(WORKER_CPUS_MIN, WORKER_CPUS_MAX),
    "seeds[]": Bound(0, SEED_MAX),
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

    def check(self, v: Any) -> Any:
        """``v`` unchanged, or a ValueError that names the range."""
        b = self.bound
        if not b.lo <= v <= b.hi:
            raise ValueError(f"{number_text(v)} is out of range {b.text()}")
        return v

    def __get_pydantic_core_schema__(self, source: Any, handler: GetCoreSchemaHandler) -> core_schema.CoreSchema:
        return core_schema.no_info_after_validator_function(self.check, handler(source))


#: the last word of a variable name that holds a credential (``OPENAI_API_KEY``, ``HF_TOKEN``,
#: ``WATSONX_APIKEY``); every key variable litellm reads for a provider ends in one of them
CREDENTIAL_WORDS = ("KEY", "APIKEY", "TOKEN", "SECRET", "PASSWORD", "PASSWD")


def credential_name(name: str) -> bool:
    """Whether an environment variable's name says it holds a credential: it is one of
    :data:`CREDENTIAL_WORDS` or ends in ``_`` and one of them (case-insensitive). ``HOME``,
    ``PATH`` or ``AZURE_API_BASE`` do not, so ``api_key_env`` cannot send them to a provider."""
    upper = name.upper()
    return any(upper == w or upper.endswith("_" + w) for w in CREDENTIAL_WORDS)


# -- field types ---------------------------------------------------------------------------------
def _not_bool(v: Any) -> Any:
    if isinstance(v, bool):
        raise ValueError("must be a number, not true/false")
    return v


#: numbers in a sweep file are numbers: YAML's true/false are refused, not read as 1/0
_NOT_BOOL = BeforeValidator(_not_bool)


def _unprintable(v: str) -> str | None:
    """The first character a terminal would interpret (control, format, line separators)."""
    for ch in v:
        if unicodedata.category(ch)[0] == "C" or unicodedata.category(ch) in ("Zl", "Zp"):
            return ch
    return None


def _printable(v: str) -> str:
    bad = _unprintable(v)
    if bad is not None:
        raise ValueError(f"must not contain control characters (found {bad!r})")
    return v


def _label(v: str) -> str:
    if v != v.strip():
        raise ValueError("must not start or end with a space")
    if not _LABEL.match(v):
        raise ValueError(
            f"may hold only letters, digits, spaces and - _ . : @ + / ( ) , = # % (no brackets or control characters), got {v!r}"
        )
    return v


def _model_string(v: str) -> str:
    if not _MODEL.match(v):
        raise ValueError(f"must be a litellm model string (printable, no spaces, brackets or backslashes), got {v!r}")
    return v


Name = Annotated[str, Field(min_length=1, max_length=NAME_MAX), AfterValidator(_printable)]
Label = Annotated[str, Field(min_length=1, max_length=NAME_MAX), AfterValidator(_label)]
Selector = Annotated[str, Field(min_length=1, max_length=SELECTOR_MAX), AfterValidator(_printable)]


def _local_path(v: str) -> str:
    """``~`` expanded and made absolute (normalised, symlinks kept), once for every component."""
    p = os.path.expanduser(v)
    if p.startswith("~"):
        raise ValueError(f"cannot expand {v!r} (no such user or no home folder)")
    return os.path.abspath(p)


def _is_uri(v: str) -> bool:
    return "://" in v


def _path_option(key: str) -> bool:
    return key.startswith("data_dir") or key.endswith("_dir")


def _check_free_form(v: dict[str, Any], what: str) -> dict[str, Any]:
    if len(v) > LIST_MAX:
        raise ValueError(f"at most {LIST_MAX} {what}")
    for k in v:
        if not isinstance(k, str) or not k or len(k) > NAME_MAX or _unprintable(k) is not None:
            raise ValueError(f"{k!r} is not a valid key (at most {NAME_MAX} printable characters)")
    return v


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, str_max_length=PATH_MAX)


class PriceSpec(_Strict):
    """USD per million tokens; ``cached_input`` (cache reads) and ``cache_write`` (tokens written
    to an explicit-breakpoint cache, Anthropic style) default to ``input``."""

    input: Annotated[float, _NOT_BOOL, Bounded("models[].prices.input")]
    output: Annotated[float, _NOT_BOOL, Bounded("models[].prices.output")]
    cached_input: Annotated[float, _NOT_BOOL, Bounded("models[].prices.cached_input")] | None = None
    cache_write: Annotated[float, _NOT_BOOL, Bounded("models[].prices.cache_write")] | None = None


#: The one mapping between a sweep model entry and the gateway's deployment
#: (:class:`workers.llm.providers.DeploymentConfig`): spec field -> config field. The sweep file
#: keeps its documented spellings; the config keeps the gateway's. ``label`` becomes the
#: config's ``name`` through :attr:`ModelSpec.name` (label, else the model string), so the
#: deployment's name - what caps, spend, the ledger journal and ``llm_calls.model_name`` are
#: kept by - is the model's unique name in the sweep. ``retries`` counts attempts after the
#: first: ``max_attempts = retries + 1``. Every ModelSpec field is here or in
#: :data:`SPEC_ONLY_FIELDS` (tests/pipeline/test_model_config.py checks it).
DEPLOYMENT_FIELDS: dict[str, str] = {
    "model": "model",
    "label": "name",
    "params": "params",
    "options": "offline_options",
    "rpm": "rpm",
    "tpm": "tpm",
    "concurrency": "max_concurrency",
    "window_s": "window_s",
    "retries": "max_attempts",
    "timeout_s": "attempt_timeout_s",
    "prices": "price",
    "api_base": "api_base",
    "api_key_env": "api_key_env",
    "max_usage_rejections": "max_usage_rejections",
}
#: model entry fields the gateway's deployment does not carry (the ledger takes the caps; the
#: preflight reads the key-name override)
SPEC_ONLY_FIELDS = frozenset({"cap_usd", "api_key_env_is_credential"})


class ModelSpec(_Strict):
    """One ``models:`` entry of a sweep: the model string, its label, the params sent with every
    call and the test-double options (part of a unit's identity), then transport settings that are
    not: rate limits, retries, timeout, prices, endpoint, cap."""

    model: Annotated[str, Field(min_length=1, max_length=LONG_MAX), AfterValidator(_model_string)]
    label: Label | None = None
    #: sent with every call (temperature override, top_p, provider options, test-double knobs)
    params: dict[str, Any] = Field(default_factory=dict)
    #: knobs of the offline/ test doubles (seed, invalid_action_rate, malformed_json_rate,
    #: chunk_size); part of the unit hash
    options: dict[str, Any] = Field(default_factory=dict)
    # --- transport: never part of a unit's identity ---
    rpm: Annotated[int, _NOT_BOOL, Bounded("models[].rpm")] | None = None
    tpm: Annotated[int, _NOT_BOOL, Bounded("models[].tpm")] | None = None
    concurrency: Annotated[int, _NOT_BOOL, Bounded("models[].concurrency")] | None = None
    #: the quota window rpm/tpm count over (60 s for real providers; shorter for test servers)
    window_s: Annotated[float, _NOT_BOOL, Bounded("models[].window_s")] | None = None
    retries: Annotated[int, _NOT_BOOL, Bounded("models[].retries")] | None = None
    timeout_s: Annotated[float, _NOT_BOOL, Bounded("models[].timeout_s")] | None = None
    #: replies with impossible usage (charged at their reservation) after which the gateway
    #: refuses the model's calls and the driver stops its units (default 3)
    max_usage_rejections: Annotated[int, _NOT_BOOL, Bounded("models[].max_usage_rejections")] | None = None
    prices: PriceSpec | None = None
    api_base: Annotated[str, Field(min_length=1, max_length=LONG_MAX), AfterValidator(_printable)] | None = None
    #: the variable named by api_key_env holds a key although its name does not say so (see
    #: :func:`credential_name`): without this such a name is refused, so that no other variable
    #: (HOME, PATH) is ever sent to a provider as a key. Before api_key_env: its check reads it.
    api_key_env_is_credential: bool = False
    api_key_env: Annotated[str, Field(max_length=NAME_MAX)] | None = None
    cap_usd: Annotated[float, _NOT_BOOL, Bounded("models[].cap_usd")] | None = None

    @property
    def name(self) -> str:
        return self.label or self.model

    @property
    def test_double(self) -> bool:
        return self.model.startswith(OFFLINE_PREFIX)

    def deployment_fields(self) -> dict[str, Any]:
        """The arguments of this entry's ``DeploymentConfig`` (:data:`DEPLOYMENT_FIELDS`); a
        transport setting left out keeps the config's default."""
        out: dict[str, Any] = {}
        for spec_field, config_field in DEPLOYMENT_FIELDS.items():
            value = getattr(self, spec_field)
            if spec_field == "label":
                value = self.name
            elif spec_field == "retries" and value is not None:
                value = value + 1
            elif spec_field == "prices" and value is not None:
                value = value.model_dump()
            elif isinstance(value, dict):
                value = dict(value)
            if value is not None:
                out[config_field] = value
        return out

    @field_validator("params")
    @classmethod
    def _params(cls, v: dict[str, Any]) -> dict[str, Any]:
        return _check_free_form(v, "params")

    @field_validator("options")
    @classmethod
    def _options(cls, v: dict[str, Any]) -> dict[str, Any]:
        return _check_free_form(v, "options")

    @field_validator("api_key_env")
    @classmethod
    def _api_key_env(cls, v: str | None, info: ValidationInfo) -> str | None:
        if v is not None and not _ENV_VAR.match(v):
            raise ValueError(f"must be an environment variable name (letters, digits, _), got {v!r}")
        if v is not None and not credential_name(v) and not info.data.get("api_key_env_is_credential"):
            raise ValueError(
                f"{v} does not name a credential (a variable ending in {', '.join('_' + w for w in CREDENTIAL_WORDS)}) "
                "and its value would be sent to the provider as the API key; "
                "if it does hold the key, add api_key_env_is_credential: true"
            )
        return v

    @model_validator(mode="after")
    def _credential_override(self) -> ModelSpec:
        if self.api_key_env_is_credential and not self.api_key_env:
            raise ValueError("api_key_env_is_credential: true needs api_key_env (the variable it vouches for)")
        return self

    @field_validator("api_base")
    @classmethod
    def _api_base_url(cls, v: str | None, info: ValidationInfo) -> str | None:
        """A provider's base URL must be one (a typo would fail every call of the night);
        ``offline/replay`` takes a run folder there instead (resolved like ``output``)."""
        model = info.data.get("model")
        if v is None or model is None:
            return v
        if not model.startswith(OFFLINE_PREFIX):
            from urllib.parse import parse_qsl, urlparse

            url = urlparse(v)
            if url.scheme not in ("http", "https") or not url.netloc or any(c.isspace() for c in v):
                raise ValueError(f"must be an http(s) URL such as http://127.0.0.1:8000/v1, got {v!r}")
            try:
                url.port  # noqa: B018 - raises on a port out of range
            except ValueError:
                raise ValueError(f"port out of range in {v!r}") from None
            secret_query = {"key", "api_key", "apikey", "token", "access_token", "password", "secret"}
            if url.username or url.password or any(k.lower() in secret_query for k, _ in parse_qsl(url.query)):
                # credentials in the URL would be stored with the spec and clash with the key
                # header at the provider; keys travel in the environment only
                raise ValueError(
                    "must not carry credentials (user:password@ or a key/token query "
                    "parameter): put the key in the variable named by api_key_env"
                )
            return v
        return v if _is_uri(v) else _local_path(v)


class MethodSpec(_Strict):
    """One ``methods:`` entry: a registered method with an optional profile, ablation and explicit
    settings (all part of a unit's identity). ``name`` is its label, else
    ``method[profile,ablation]``."""

    method: Name
    label: Label | None = None
    profile: Name | None = None
    ablation: Name | None = None
    settings: dict[str, Any] = Field(default_factory=dict)
    #: ``ours`` (default): our own prompt text; ``release``: the authors' released prompt and
    #: demonstration files, read at run time (``recap data fetch recap-release``; workers/release)
    prompts: Literal["ours", "release"] = "ours"
    #: the step-cap multiplier of this method's units (None: the sweep's ``step_multiplier``):
    #: the released configs give each method its own (Act x2, Standard x1.5 on Robotouille)
    step_multiplier: Annotated[float, _NOT_BOOL, Bounded("methods[].step_multiplier")] | None = None
    #: per task, over ``step_multiplier``: ``<benchmark>/<task selector>`` (``robotouille/synchronous/2``)
    #: -> multiplier. Each key is resolved by the benchmark's own selectors when the sweep is
    #: planned (:func:`pipeline.units.method_step_multipliers`); part of the unit's identity
    #: through the multiplier it gives
    step_multipliers: Annotated[
        dict[Selector, Annotated[float, _NOT_BOOL, Bounded("methods[].step_multipliers{}")]],
        Field(max_length=SELECTORS_MAX),
    ] = Field(default_factory=dict)

    @field_validator("settings")
    @classmethod
    def _settings(cls, v: dict[str, Any]) -> dict[str, Any]:
        if "prompts" in v:
            raise ValueError("prompts is the method entry's own field (prompts: release), not a setting")
        return _check_free_form(v, "settings")

    @field_validator("step_multipliers")
    @classmethod
    def _step_multipliers(cls, v: dict[str, float]) -> dict[str, float]:
        for key in v:
            bench, _, selector = key.partition("/")
            if not bench or not selector:
                raise ValueError(f"key {key!r} must be <benchmark>/<task selector>, e.g. robotouille/synchronous/2")
        return v

    @property
    def name(self) -> str:
        if self.label:
            return self.label
        suffix = [x for x in (self.profile, None if self.ablation in (None, "original") else self.ablation) if x]
        if self.prompts == "release":
            suffix.append("release-prompts")
        return self.method + (f"[{','.join(suffix)}]" if suffix else "")


class EnvSpec(_Strict):
    """One ``environments:`` entry: a benchmark and which of its instances to run (selectors,
    explicit ids, a per-selector limit), plus make() options that are not part of a unit's identity."""

    benchmark: Name
    #: selectors handed to the benchmark's list_instances (split, task, task type...)
    tasks: list[Selector] = Field(default_factory=list, max_length=SELECTORS_MAX)
    #: explicit instance ids
    instances: list[Selector] = Field(default_factory=list, max_length=INSTANCES_MAX)
    #: at most this many instances per selector (in the benchmark's fixed order)
    limit: Annotated[int, _NOT_BOOL, Bounded("environments[].limit")] | None = None
    #: options for the benchmark's make() (data_dir ...); not part of the unit hash. Path
    #: options (data_dir, *_dir) are resolved here (~ expanded, made absolute).
    options: dict[str, Any] = Field(default_factory=dict)

    @field_validator("options")
    @classmethod
    def _options(cls, v: dict[str, Any]) -> dict[str, Any]:
        _check_free_form(v, "options")
        out = dict(v)
        for k, val in v.items():
            if _path_option(k) and isinstance(val, str) and val and not _is_uri(val):
                out[k] = _local_path(val)
        return out


class LimitsSpec(_Strict):
    """Per-episode limits, mapped onto AgentConfig max_llm_calls / max_episode_tokens /
    max_episode_cost_usd (a method's own settings win)."""

    llm_calls: Annotated[int, _NOT_BOOL, Bounded("limits.llm_calls")] | None = None
    tokens: Annotated[int, _NOT_BOOL, Bounded("limits.tokens")] | None = None
    usd: Annotated[float, _NOT_BOOL, Bounded("limits.usd")] | None = None

    def agent_settings(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        if self.llm_calls is not None:
            out["max_llm_calls"] = self.llm_calls
        if self.tokens is not None:
            out["max_episode_tokens"] = self.tokens
        if self.usd is not None:
            out["max_episode_cost_usd"] = self.usd
        return out


_HOST_LABEL = r"[A-Za-z0-9](?:[A-Za-z0-9\-]{0,61}[A-Za-z0-9])?"
_ADDRESS = re.compile(rf"^(?:ray://)?(?P<host>{_HOST_LABEL}(?:\.{_HOST_LABEL})*|\[[0-9A-Fa-f:.%A-Za-z]+\]):(?P<port>\d{{1,5}})$")


def check_ray_address(v: str) -> str:
    """``auto``, ``local``, ``host:port`` or ``ray://host:port`` with a port in 1..65535."""
    if v in ("auto", "local"):
        return v
    m = _ADDRESS.match(v)
    ok = m is not None and 1 <= int(m["port"]) <= 65535
    if m is not None and ok and m["host"].startswith("["):
        try:
            ipaddress.IPv6Address(m["host"][1:-1])
        except ValueError:
            ok = False
    if not ok:
        raise ValueError(f"must be auto, host:port or ray://host:port with a port in 1..65535, got {v!r}")
    return v


class RaySpec(_Strict):
    """The ``ray:`` section: the cluster to join (``address``; None: start a local Ray unless the
    command line names one), the resources of a Ray started here, and the CPU share of each episode
    worker."""

    address: Annotated[str, Field(max_length=NAME_MAX), AfterValidator(check_ray_address)] | None = None
    num_cpus: Annotated[int, _NOT_BOOL, Bounded("ray.num_cpus")] | None = None
    dashboard: bool = False
    object_store_mb: Annotated[int, _NOT_BOOL, Bounded("ray.object_store_mb")] = 256
    #: CPU share of one episode worker actor (small: workers wait on the model)
    worker_cpus: Annotated[float, _NOT_BOOL, Bounded("ray.worker_cpus")] = 0.05


class SweepSpec(_Strict):
    """A validated sweep file: models x methods x environments x seeds make the units; limits, caps,
    attempts, start order and Ray settings say how they run. Unknown keys are errors."""

    run: Annotated[str, Field(max_length=NAME_MAX)]
    output: Annotated[str, Field(min_length=1, max_length=PATH_MAX)]
    models: list[ModelSpec] = Field(min_length=1, max_length=LIST_MAX)
    methods: list[MethodSpec] = Field(min_length=1, max_length=LIST_MAX)
    environments: list[EnvSpec] = Field(min_length=1, max_length=LIST_MAX)
    seeds: list[Annotated[int, _NOT_BOOL, Bounded("seeds[]")]] = Field(
        default_factory=lambda: [0], min_length=1, max_length=SEEDS_MAX
    )
    step_multiplier: Annotated[float, _NOT_BOOL, Bounded("step_multiplier")] = 4.0
    limits: LimitsSpec = Field(default_factory=LimitsSpec)
    run_cap_usd: Annotated[float, _NOT_BOOL, Bounded("run_cap_usd")] | None = None
    workers: Annotated[int, _NOT_BOOL, Bounded("workers")] = 4
    max_attempts: Annotated[int, _NOT_BOOL, Bounded("max_attempts")] = 3
    #: the order units start in (not part of any unit hash): ``interleaved`` (default) takes the
    #: arms (method x model) in turn and, within an arm, instances in a shuffle seeded by the run
    #: name, so a cap that binds early leaves a balanced subsample; ``plan`` is the plan's own
    #: order (instances, then methods, models, seeds). See :func:`pipeline.units.order_units`.
    order: Literal["interleaved", "plan"] = "interleaved"
    ray: RaySpec = Field(default_factory=RaySpec)

    @field_validator("run")
    @classmethod
    def _run_name(cls, v: str) -> str:
        if not _NAME.match(v):
            raise ValueError("must be letters, digits, '.', '_' or '-' (starting with a letter or digit)")
        return v

    @field_validator("output")
    @classmethod
    def _output(cls, v: str) -> str:
        """Resolved once: every component (store, sink, gateway, mirror) sees this string."""
        _printable(v)
        if not _is_uri(v):
            return _local_path(v)
        scheme, rest = v.split("://", 1)
        if scheme.lower() not in URI_SCHEMES:
            raise ValueError(f"unknown URI scheme {scheme!r}; use a local folder or {', '.join(s + '://' for s in URI_SCHEMES)}")
        if any(c.isspace() for c in v):
            raise ValueError(f"an object-store URI must not contain spaces, got {v!r}")
        if scheme.lower() == "file":
            if not rest.startswith("/"):
                raise ValueError(f"a file:// URI needs an absolute path (file:///abs/path), got {v!r}")
        elif not rest.split("?", 1)[0].strip("/"):
            raise ValueError(f"{v!r} names no bucket or container")
        return v

    @model_validator(mode="after")
    def _unique(self) -> SweepSpec:
        for what, names in (("models", [m.name for m in self.models]), ("methods", [m.name for m in self.methods])):
            seen: set[str] = set()
            for n in names:
                if n in seen:
                    raise ValueError(f"{what}: two entries are both named {n!r}; give them distinct 'label's")
                seen.add(n)
        if len(set(self.seeds)) != len(self.seeds):
            raise ValueError("seeds: repeated seed")
        for i, e in enumerate(self.environments):
            if not e.tasks and not e.instances:
                raise ValueError(f"environments[{i}]: give 'tasks' (selectors) or 'instances' (ids)")
        if sum(len(e.instances) for e in self.environments) > INSTANCES_TOTAL_MAX:
            raise ValueError(f"environments: at most {INSTANCES_TOTAL_MAX} instance ids in all")
        return self

    def model(self, name: str) -> ModelSpec:
        for m in self.models:
            if m.name == name:
                return m
        raise KeyError(name)

    def method(self, name: str) -> MethodSpec:
        for m in self.methods:
            if m.name == name:
                return m
        raise KeyError(name)


def _loc(loc: tuple[Any, ...]) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out


def _pydantic_message(source: str, exc: ValidationError) -> str:
    errors = exc.errors()
    first = errors[0]
    loc = _loc(tuple(x for x in first.get("loc", ()) if not str(x).startswith("function-")))
    msg = first.get("msg", "invalid")
    if first.get("type") == "extra_forbidden":
        msg = "unknown field"
    elif first.get("type") == "missing":
        msg = "required field is missing"
    msg = msg.removeprefix("Value error, ")
    more = f" (and {len(errors) - 1} more problem{'s' if len(errors) > 2 else ''})" if len(errors) > 1 else ""
    return f"{source}: {loc + ': ' if loc else ''}{msg}{more}"


# --------------------------------------------------------------------------------------------
# the YAML reader: no aliases, no duplicate keys, bounded sizes
# --------------------------------------------------------------------------------------------
class _Refused(Exception):
    """A YAML construct the sweep file may not use; the message names the line."""


def _line(node_or_event: Any) -> int:
    mark = getattr(node_or_event, "start_mark", None)
    return mark.line + 1 if mark is not None else 0


_MERGE_TAG = "tag:yaml.org,2002:merge"


class _SpecLoader(yaml.SafeLoader):
    """SafeLoader that refuses anchors/aliases/merge keys, duplicate keys, huge scalars and deep
    nesting, each with the line it is on."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent: Any, index: Any) -> Any:
        event = self.peek_event()
        if isinstance(event, yaml.AliasEvent):
            raise _Refused(f"YAML aliases are not allowed (*{event.anchor} at line {_line(event)}); write the value out")
        anchor = getattr(event, "anchor", None)
        if anchor is not None:
            raise _Refused(f"YAML anchors are not allowed (&{anchor} at line {_line(event)}); write the value out")
        if isinstance(event, yaml.ScalarEvent) and len(event.value) > MAX_SCALAR_CHARS:
            raise _Refused(f"a value of {len(event.value)} characters at line {_line(event)}; at most {MAX_SCALAR_CHARS}")
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                raise _Refused(f"nested deeper than {MAX_DEPTH} levels at line {_line(event)}")
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_mapping(self, node: Any, deep: bool = False) -> Any:
        if isinstance(node, yaml.MappingNode):
            seen: dict[Any, int] = {}
            for key_node, _ in node.value:
                if key_node.tag == _MERGE_TAG:
                    raise _Refused(f"YAML merge keys (<<) are not allowed (line {_line(key_node)})")
                key = self.construct_object(key_node, deep=True)
                try:
                    first = seen.get(key)
                except TypeError:
                    raise _Refused(f"a mapping key at line {_line(key_node)} is not a plain value") from None
                if first is not None:
                    raise _Refused(f"duplicate key {key!r} at line {_line(key_node)} (first at line {first})")
                seen[key] = _line(key_node)
        return super().construct_mapping(node, deep=deep)

    def construct_yaml_int(self, node: Any) -> int:
        try:
            return super().construct_yaml_int(node)
        except ValueError:
            raise _Refused(f"integer {node.value[:20]!r}... at line {_line(node)} is too large") from None


_SpecLoader.add_constructor("tag:yaml.org,2002:int", _SpecLoader.construct_yaml_int)


def _check_values(data: Any, loc: tuple[Any, ...] = ()) -> None:
    """Every number in the file finite and within a signed 64-bit column (free-form mappings
    such as params, options and settings included); only plain JSON-like values (no dates,
    binary or sets, which would reach JSON columns and hashes as something else)."""
    if isinstance(data, dict):
        for k, v in data.items():
            _check_values(v, (*loc, k))
    elif isinstance(data, list):
        for i, v in enumerate(data):
            _check_values(v, (*loc, i))
    elif data is not None and not isinstance(data, (str, int, float)):
        raise _Refused(f"{_loc(loc) or 'value'}: a YAML {type(data).__name__} is not allowed here; quote it to make it a string")
    elif isinstance(data, float) and not math.isfinite(data):
        raise _Refused(f"{_loc(loc) or 'value'}: must be a finite number, got {data}")
    elif isinstance(data, int) and not isinstance(data, bool) and not -INT64_MAX - 1 <= data <= INT64_MAX:
        raise _Refused(f"{_loc(loc) or 'value'}: integer out of range (-2**63 .. 2**63-1)")


def _check_events(text: str, loader: Any) -> None:
    """One pass over the parser's events (libyaml's when there is one: fast): anchors, aliases,
    huge scalars and deep nesting are refused before anything is composed."""
    depth = 0
    for event in yaml.parse(text, Loader=loader):
        if isinstance(event, yaml.AliasEvent):
            raise _Refused(f"YAML aliases are not allowed (*{event.anchor} at line {_line(event)}); write the value out")
        anchor = getattr(event, "anchor", None)
        if anchor is not None:
            raise _Refused(f"YAML anchors are not allowed (&{anchor} at line {_line(event)}); write the value out")
        if isinstance(event, yaml.ScalarEvent) and len(event.value) > MAX_SCALAR_CHARS:
            raise _Refused(f"a value of {len(event.value)} characters at line {_line(event)}; at most {MAX_SCALAR_CHARS}")
        if isinstance(event, yaml.CollectionStartEvent):
            depth += 1
            if depth > MAX_DEPTH:
                raise _Refused(f"nested deeper than {MAX_DEPTH} levels at line {_line(event)}")
        elif isinstance(event, yaml.CollectionEndEvent):
            depth -= 1


#: malformed files up to this size are re-read by the (slower) pure-Python parser for its message
_PY_MESSAGE_MAX = 64 * 1024


def _yaml_data(text: str) -> Any:
    fast = getattr(yaml, "CSafeLoader", None)
    if fast is None:
        loader = _SpecLoader(text)
        try:
            return loader.get_single_data()
        finally:
            loader.dispose()
    try:
        _check_events(text, fast)
        node = yaml.compose(text, Loader=fast)
    except yaml.YAMLError:
        if len(text) > _PY_MESSAGE_MAX:
            raise
        # the pure-Python parser's message (and line) for the same problem: the one users know
        loader = _SpecLoader(text)
        try:
            loader.get_single_data()
        finally:
            loader.dispose()
        raise
    if node is None:
        return None
    constructor = _SpecLoader("")
    try:
        return constructor.construct_document(node)
    finally:
        constructor.dispose()


def load_yaml(text: str, source: str = "spec") -> Any:
    """The YAML data of a sweep file (see the module docstring for what is refused)."""
    if len(text) > MAX_SPEC_BYTES or len(text.encode("utf-8", "surrogatepass")) > MAX_SPEC_BYTES:
        raise SpecError(f"{source}: larger than {MAX_SPEC_BYTES} bytes; a sweep file may be at most 1 MiB")
    try:
        data = _yaml_data(text)
        _check_values(data)
        return data
    except _Refused as exc:
        raise SpecError(f"{source}: {exc}") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise SpecError(f"{source}: malformed YAML{where}: {problem}") from None
    except (ValueError, OverflowError, RecursionError, MemoryError) as exc:
        raise SpecError(f"{source}: malformed YAML: {type(exc).__name__}: {str(exc)[:200]}") from None


def parse_spec(text: str, source: str = "spec") -> SweepSpec:
    """Parse and validate YAML text; every problem is one :class:`SpecError` line."""
    data = load_yaml(text, source)
    if not isinstance(data, dict):
        raise SpecError(f"{source}: the sweep file must be a YAML mapping (run:, output:, models:, ...)")
    try:
        return SweepSpec.model_validate(data)
    except ValidationError as exc:
        raise SpecError(_pydantic_message(source, exc)) from None


def read_spec_text(path: str | Path) -> str:
    """The text of a sweep file: a regular file of at most MAX_SPEC_BYTES of UTF-8. A device
    (``/dev/zero``), FIFO or socket is refused before it is read (or opened: a FIFO's open
    would block)."""
    p = Path(path)
    name = repr(str(p))
    try:
        st = os.stat(p)
    except (FileNotFoundError, NotADirectoryError):
        raise SpecError(f"sweep file {name} does not exist") from None
    except OSError as exc:
        raise SpecError(f"sweep file {name} cannot be read: {exc.strerror or exc}") from None
    if stat.S_ISDIR(st.st_mode):
        raise SpecError(f"sweep file {name} cannot be read: it is a folder")
    if not stat.S_ISREG(st.st_mode):
        raise SpecError(f"sweep file {name} cannot be read: not a regular file (a device, FIFO or socket)")
    if st.st_size > MAX_SPEC_BYTES:
        raise SpecError(f"sweep file {name} is {st.st_size} bytes; a sweep file may be at most 1 MiB")
    try:
        fd = os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as exc:
        raise SpecError(f"sweep file {name} cannot be read: {exc.strerror or exc}") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):  # swapped since the stat
            raise SpecError(f"sweep file {name} cannot be read: not a regular file (a device, FIFO or socket)")
        with os.fdopen(fd, "rb", closefd=False) as fh:
            raw = fh.read(MAX_SPEC_BYTES + 1)
    except OSError as exc:
        raise SpecError(f"sweep file {name} cannot be read: {exc.strerror or exc}") from None
    finally:
        os.close(fd)
    if len(raw) > MAX_SPEC_BYTES:
        raise SpecError(f"sweep file {name} is larger than {MAX_SPEC_BYTES} bytes; a sweep file may be at most 1 MiB")
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SpecError(
            f"sweep file {name} cannot be read: not UTF-8 text (byte {raw[exc.start]:#04x} at offset {exc.start})"
        ) from None


def load_spec(path: str | Path) -> tuple[SweepSpec, str]:
    """(validated spec, its YAML text) from a file."""
    text = read_spec_text(path)
    return parse_spec(text, Path(path).name), text


def with_overrides(spec: SweepSpec, **changes: Any) -> SweepSpec:
    """A copy with top-level fields replaced (CLI flags such as --workers, --run-cap)."""
    changes = {k: v for k, v in changes.items() if v is not None}
    if not changes:
        return spec
    data = spec.model_dump()
    ray_changes = {k: changes.pop(k) for k in ("address",) if k in changes}
    data.update(changes)
    data["ray"].update(ray_changes)
    try:
        return SweepSpec.model_validate(data)
    except ValidationError as exc:
        raise SpecError(_pydantic_message("command line", exc)) from None


def text_hash(text: str) -> str:
    """A short content hash of ``text`` (the first 16 hex digits of its sha256), e.g. the
    ``spec_hash`` of the sweep file a run records."""
    return hashlib.sha256(text.encode()).hexdigest()[:16]


# --------------------------------------------------------------------------------------------
# object-store outputs: usable before anything is written
# --------------------------------------------------------------------------------------------
#: seconds the reachability check of an object-store output may take (env override)
STORE_CHECK_TIMEOUT_S = 15.0

_FS_MODULES = {
    "s3": "pyarrow._s3fs",
    "gs": "pyarrow._gcsfs",
    "gcs": "pyarrow._gcsfs",
    "hdfs": "pyarrow._hdfs",
    "abfs": "pyarrow._azurefs",
    "abfss": "pyarrow._azurefs",
}

_PROBE = """
import sys
try:
    import pyarrow.fs as pafs
    fs, root = pafs.FileSystem.from_uri(sys.argv[1])
    info = fs.get_file_info(root.rstrip("/") or root)
    if info.type == pafs.FileType.File:
        print("it is a file, not a folder")
        sys.exit(1)
except BaseException as exc:
    print(f"{type(exc).__name__}: {str(exc).strip().splitlines()[0] if str(exc).strip() else ''}"[:300])
    sys.exit(1)
"""


def _endpoint(scheme: str, location: str) -> tuple[str, int]:
    """(host, port) an object-store URI talks to."""
    from urllib.parse import parse_qs, urlsplit

    u = urlsplit(location)
    query = {k: v[-1] for k, v in parse_qs(u.query).items()}

    def host_port(text: str, default_port: int) -> tuple[str, int]:
        if "://" not in text:
            text = "//" + text
        hp = urlsplit(text)
        return hp.hostname or "", hp.port or (443 if hp.scheme == "https" else 80 if hp.scheme == "http" else default_port)

    if scheme == "s3":
        override = query.get("endpoint_override") or os.environ.get("AWS_ENDPOINT_URL_S3") or os.environ.get("AWS_ENDPOINT_URL")
        if override:
            return host_port(override, 80 if query.get("scheme") == "http" else 443)
        return "s3.amazonaws.com", 443
    if scheme in ("gs", "gcs"):
        override = query.get("endpoint_override") or os.environ.get("STORAGE_EMULATOR_HOST")
        if override:
            return host_port(override, 80 if query.get("scheme") == "http" else 443)
        return "storage.googleapis.com", 443
    if scheme == "hdfs":
        return u.hostname or "", u.port or 8020
    # abfs://container@account.dfs.core.windows.net/path
    return (u.hostname or "").rpartition("@")[2], 443


def _reach(host: str, port: int, timeout: float) -> str | None:
    """Why ``host:port`` cannot be reached within ``timeout`` seconds (None when it can);
    name resolution runs in a daemon thread so a stuck resolver cannot hang the check."""
    import socket
    import threading

    if not host:
        return "no host in the URI"
    result: dict[str, Any] = {}

    def resolve() -> None:
        try:
            result["addrs"] = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
        except OSError as exc:
            result["error"] = exc

    t = threading.Thread(target=resolve, daemon=True)
    t.start()
    t.join(timeout)
    if t.is_alive():
        return f"name resolution of {host} took longer than {timeout:g} s"
    if "error" in result:
        return f"cannot resolve {host} ({result['error']})"
    last: OSError | None = None
    for family, socktype, proto, _, addr in result.get("addrs", []):
        s = socket.socket(family, socktype, proto)
        s.settimeout(timeout)
        try:
            s.connect(addr)
            return None
        except OSError as exc:
            last = exc
        finally:
            s.close()
    return f"cannot connect to {host}:{port} ({last})"


def check_output_location(location: str, *, timeout_s: float | None = None) -> None:
    """An object-store output (or run folder) must be usable now, not at the first write of a
    started run: the scheme is known, this pyarrow supports it, its endpoint answers, and the
    folder can be listed with the credentials at hand. Bounded in time (``timeout_s``, default
    ``RECAP_STORE_CHECK_TIMEOUT_S`` or 15 s); writes nothing. A local path or ``file://`` URI
    passes (the run store checks that it can be created)."""
    import importlib
    import subprocess
    import sys

    if not _is_uri(location):
        return
    scheme = location.split("://", 1)[0].lower()
    if scheme not in URI_SCHEMES:
        raise SpecError(
            f"output {location}: unknown URI scheme {scheme!r}; use a local folder or {', '.join(s + '://' for s in URI_SCHEMES)}"
        )
    if scheme == "file":
        return
    if timeout_s is None:
        try:
            timeout_s = float(os.environ.get("RECAP_STORE_CHECK_TIMEOUT_S", STORE_CHECK_TIMEOUT_S))
        except ValueError:
            timeout_s = STORE_CHECK_TIMEOUT_S
    try:
        importlib.import_module(_FS_MODULES[scheme])
    except ImportError:
        raise SpecError(
            f"output {location}: this pyarrow cannot write {scheme}:// (no {scheme} support built in); use a local folder"
        ) from None
    host, port = _endpoint(scheme, location)
    why = _reach(host, port, min(timeout_s, 5.0))
    if why is not None:
        raise SpecError(f"output {location} cannot be used: {why}; check the network or use a local folder")
    try:
        r = subprocess.run(
            [sys.executable, "-c", _PROBE, location], capture_output=True, text=True, timeout=timeout_s, stdin=subprocess.DEVNULL
        )
    except subprocess.TimeoutExpired:
        raise SpecError(
            f"output {location} cannot be used: no answer within {timeout_s:g} s "
            "(check credentials and network, or use a local folder)"
        ) from None
    except OSError as exc:
        raise SpecError(f"output {location} cannot be checked: {exc}") from None
    if r.returncode != 0:
        detail = (r.stdout.strip().splitlines() or r.stderr.strip().splitlines()[-1:] or ["unknown error"])[-1]
        raise SpecError(f"output {location} cannot be used: {detail}")


def check_ray_address_reachable(address: str | None, timeout_s: float = 5.0) -> None:
    """A ``host:port`` / ``ray://host:port`` cluster address must accept a TCP connection within
    ``timeout_s`` (``ray.init`` on a dead address retries for a long time); ``auto``/``local``
    and no address pass. Writes nothing."""
    if not address or address in ("auto", "local"):
        return
    check_ray_address(address)
    m = _ADDRESS.match(address)
    assert m is not None
    why = _reach(m["host"].strip("[]"), int(m["port"]), timeout_s)
    if why is not None:
        raise SpecError(f"ray.address {address}: {why}; is the cluster up (ray status)?")
