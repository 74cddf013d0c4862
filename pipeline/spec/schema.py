"""The sweep file's schema: the pydantic models that check every section and field before anything runs.

Why pydantic: every field is checked before anything runs, unknown keys are errors (a typo such
as ``rmp:`` must not silently drop a rate limit), and the first problem is reported as one line
naming the file and the field (``sweep.yaml: models[0].rpm: must be > 0``). The file format and
its rules are described in :mod:`pipeline.spec`.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal
from urllib.parse import parse_qsl, urlparse

from pydantic import AfterValidator, AliasChoices, Field, ValidationInfo, field_validator, model_validator

from pipeline.spec.bounds import (
    INSTANCES_MAX,
    INSTANCES_TOTAL_MAX,
    LIST_MAX,
    LONG_MAX,
    NAME_MAX,
    PATH_MAX,
    SAMPLING_SEEDS_MAX,
    SELECTORS_MAX,
    Bounded,
)
from pipeline.spec.fields import (
    CREDENTIAL_WORDS,
    ENV_VAR,
    NOT_BOOL,
    OFFLINE_PREFIX,
    RUN_NAME,
    URI_SCHEMES,
    Label,
    Name,
    Selector,
    StrictModel,
    check_free_form,
    check_ray_address,
    credential_name,
    is_uri,
    local_path,
    model_string,
    path_option,
    printable,
)
from pipeline.spec.serving import ENGINES, TEST_DOUBLE_ENGINE, ServeSpec

#: the sweep file's old name of ``sampling_seeds`` (still read; see :class:`SweepSpec`)
OLD_SEEDS_KEY = "seeds"


class PriceSpec(StrictModel):
    """USD per million tokens; ``cached_input`` (cache reads) and ``cache_write`` (tokens written
    to an explicit-breakpoint cache, Anthropic style) default to ``input``. A served model
    (``serve:``) is priced by the hour it holds its replicas instead: ``gpu_hour`` (per GPU) or
    ``replica_hour`` (per replica, for replicas without a GPU); its tokens cost nothing more."""

    input: Annotated[float, NOT_BOOL, Bounded("models[].prices.input")] | None = None
    output: Annotated[float, NOT_BOOL, Bounded("models[].prices.output")] | None = None
    cached_input: Annotated[float, NOT_BOOL, Bounded("models[].prices.cached_input")] | None = None
    cache_write: Annotated[float, NOT_BOOL, Bounded("models[].prices.cache_write")] | None = None
    #: (left out of ``model_dump``: the token price table never sees the hourly prices)
    gpu_hour: Annotated[float, NOT_BOOL, Bounded("models[].prices.gpu_hour")] | None = Field(default=None, exclude=True)
    replica_hour: Annotated[float, NOT_BOOL, Bounded("models[].prices.replica_hour")] | None = Field(default=None, exclude=True)

    @model_validator(mode="after")
    def _one_kind(self) -> PriceSpec:
        hourly = self.gpu_hour is not None or self.replica_hour is not None
        tokens = self.input is not None or self.output is not None
        if hourly and (tokens or self.cached_input is not None or self.cache_write is not None):
            raise ValueError("give token prices (input, output) or an hourly price (gpu_hour or replica_hour), not both")
        if self.gpu_hour is not None and self.replica_hour is not None:
            raise ValueError("give gpu_hour or replica_hour, not both")
        if not hourly and (self.input is None or self.output is None):
            raise ValueError("give input and output (USD per million tokens), or gpu_hour / replica_hour for a served model")
        return self

    @property
    def hourly(self) -> bool:
        return self.gpu_hour is not None or self.replica_hour is not None

    def token_prices(self) -> dict[str, Any] | None:
        """The per-token prices as the price table takes them (None for an hourly price)."""
        if self.hourly:
            return None
        return self.model_dump()


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
#: preflight reads the key-name override; the backend starts the gateway shards; the session
#: deploys a served model)
SPEC_ONLY_FIELDS = frozenset({"cap_usd", "api_key_env_is_credential", "gateway_shards", "serve"})


class ModelSpec(StrictModel):
    """One ``models:`` entry of a sweep: the model string, its label, the params sent with every
    call and the test-double options (part of a unit's identity), then transport settings that are
    not: rate limits, retries, timeout, prices, endpoint, cap."""

    model: Annotated[str, Field(min_length=1, max_length=LONG_MAX), AfterValidator(model_string)]
    label: Label | None = None
    #: sent with every call (temperature override, top_p, provider options, test-double knobs)
    params: dict[str, Any] = Field(default_factory=dict)
    #: knobs of the offline/ test doubles (noise_seed - old name seed -, invalid_action_rate,
    #: malformed_json_rate, chunk_size); part of the unit hash (``noise_seed`` hashed as ``seed``)
    options: dict[str, Any] = Field(default_factory=dict)
    # --- transport: never part of a unit's identity ---
    rpm: Annotated[int, NOT_BOOL, Bounded("models[].rpm")] | None = None
    tpm: Annotated[int, NOT_BOOL, Bounded("models[].tpm")] | None = None
    concurrency: Annotated[int, NOT_BOOL, Bounded("models[].concurrency")] | None = None
    #: the quota window rpm/tpm count over (60 s for real providers; shorter for test servers)
    window_s: Annotated[float, NOT_BOOL, Bounded("models[].window_s")] | None = None
    retries: Annotated[int, NOT_BOOL, Bounded("models[].retries")] | None = None
    timeout_s: Annotated[float, NOT_BOOL, Bounded("models[].timeout_s")] | None = None
    #: replies with impossible usage (charged at their reservation) after which the gateway
    #: refuses the model's calls and the driver stops its units (default 3)
    max_usage_rejections: Annotated[int, NOT_BOOL, Bounded("models[].max_usage_rejections")] | None = None
    prices: PriceSpec | None = None
    api_base: Annotated[str, Field(min_length=1, max_length=LONG_MAX), AfterValidator(printable)] | None = None
    #: the variable named by api_key_env holds a key although its name does not say so (see
    #: :func:`credential_name`): without this such a name is refused, so that no other variable
    #: (HOME, PATH) is ever sent to a provider as a key. Before api_key_env: its check reads it.
    api_key_env_is_credential: bool = False
    api_key_env: Annotated[str, Field(max_length=NAME_MAX)] | None = None
    cap_usd: Annotated[float, NOT_BOOL, Bounded("models[].cap_usd")] | None = None
    #: gateway actors for this model (default 1): more than one share its rpm/tpm quota and the
    #: dollar caps through leases from one quota actor (:mod:`workers.gateway.quota`); episode
    #: workers take them round robin. For a quota one gateway process cannot keep up with.
    gateway_shards: Annotated[int, NOT_BOOL, Bounded("models[].gateway_shards")] | None = None
    #: deployed by the sweep on its Ray cluster (:mod:`pipeline.spec.serving`, :mod:`pipeline.serving`)
    serve: ServeSpec | None = None

    @property
    def name(self) -> str:
        return self.label or self.model

    def token_prices(self) -> dict[str, Any] | None:
        """Per-million-token prices for the price table: the entry's own, ``0`` for a served model
        (its replica-hours are what it costs), None to use the table's."""
        if self.serve is not None:
            return {"input": 0.0, "output": 0.0}
        return self.prices.token_prices() if self.prices is not None else None

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
            elif spec_field == "prices":
                value = self.token_prices()
            elif isinstance(value, dict):
                value = dict(value)
            if value is not None:
                out[config_field] = value
        return out

    @field_validator("params")
    @classmethod
    def _params(cls, v: dict[str, Any]) -> dict[str, Any]:
        return check_free_form(v, "params")

    @field_validator("options")
    @classmethod
    def _options(cls, v: dict[str, Any]) -> dict[str, Any]:
        return check_free_form(v, "options")

    @field_validator("api_key_env")
    @classmethod
    def _api_key_env(cls, v: str | None, info: ValidationInfo) -> str | None:
        if v is not None and not ENV_VAR.match(v):
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

    @model_validator(mode="after")
    def _served(self) -> ModelSpec:
        """A served model's endpoint is the sweep's own (no ``api_base``), its engine is known,
        a real engine has weights and a test double stays one (``offline/``)."""
        if self.serve is None:
            if self.prices is not None and self.prices.hourly:
                raise ValueError("prices.gpu_hour / replica_hour are for a model the sweep serves (give serve:)")
            return self
        if self.api_base is not None:
            raise ValueError("serve: the sweep serves this model itself; leave api_base out")
        if self.prices is not None and not self.prices.hourly:
            raise ValueError("a served model is priced by the hour: prices: {gpu_hour: X} or {replica_hour: X}")
        engine = self.serve.engine_for(self.model, OFFLINE_PREFIX)
        if not engine:
            raise ValueError(f"serve.engine: name the engine ({', '.join(ENGINES)})")
        if engine == TEST_DOUBLE_ENGINE:
            if self.model not in (OFFLINE_PREFIX + "expert", OFFLINE_PREFIX + "random"):
                raise ValueError(f"serve.engine test-double serves offline/expert or offline/random, not {self.model!r}")
        elif self.test_double:
            raise ValueError(f"serve.engine {engine} serves open weights; {self.model!r} is a test double (engine: test-double)")
        elif not self.serve.weights:
            raise ValueError(f"serve.weights: give the weights {engine} serves (a hub id or a local path)")
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
        return v if is_uri(v) else local_path(v)


class MethodSpec(StrictModel):
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
    step_multiplier: Annotated[float, NOT_BOOL, Bounded("methods[].step_multiplier")] | None = None
    #: per task, over ``step_multiplier``: ``<benchmark>/<task selector>`` (``robotouille/synchronous/2``)
    #: -> multiplier. Each key is resolved by the benchmark's own selectors when the sweep is
    #: planned (:func:`pipeline.units.method_step_multipliers`); part of the unit's identity
    #: through the multiplier it gives
    step_multipliers: Annotated[
        dict[Selector, Annotated[float, NOT_BOOL, Bounded("methods[].step_multipliers{}")]],
        Field(max_length=SELECTORS_MAX),
    ] = Field(default_factory=dict)

    @field_validator("settings")
    @classmethod
    def _settings(cls, v: dict[str, Any]) -> dict[str, Any]:
        if "prompts" in v:
            raise ValueError("prompts is the method entry's own field (prompts: release), not a setting")
        return check_free_form(v, "settings")

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


class EnvSpec(StrictModel):
    """One ``environments:`` entry: a benchmark and which of its instances to run (selectors,
    explicit ids, a per-selector limit), plus the make() options the benchmark declares."""

    benchmark: Name
    #: selectors handed to the benchmark's list_instances (split, task, task type...)
    tasks: list[Selector] = Field(default_factory=list, max_length=SELECTORS_MAX)
    #: explicit instance ids
    instances: list[Selector] = Field(default_factory=list, max_length=INSTANCES_MAX)
    #: at most this many instances per selector (in the benchmark's fixed order)
    limit: Annotated[int, NOT_BOOL, Bounded("environments[].limit")] | None = None
    #: options for the benchmark's make() (data_dir ...): only those it declares
    #: (:mod:`workers.envs.options`); those that change what an episode does are part of the unit
    #: hash (when not their default), those that change how it is run are not. Path
    #: options (data_dir, *_dir) are resolved here (~ expanded, made absolute).
    options: dict[str, Any] = Field(default_factory=dict)

    @field_validator("options")
    @classmethod
    def _options(cls, v: dict[str, Any]) -> dict[str, Any]:
        check_free_form(v, "options")
        out = dict(v)
        for k, val in v.items():
            if path_option(k) and isinstance(val, str) and val and not is_uri(val):
                out[k] = local_path(val)
        return out


class LimitsSpec(StrictModel):
    """Per-episode limits, mapped onto AgentConfig max_llm_calls / max_episode_tokens /
    max_episode_cost_usd (a method's own settings win)."""

    llm_calls: Annotated[int, NOT_BOOL, Bounded("limits.llm_calls")] | None = None
    tokens: Annotated[int, NOT_BOOL, Bounded("limits.tokens")] | None = None
    usd: Annotated[float, NOT_BOOL, Bounded("limits.usd")] | None = None

    def agent_settings(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        if self.llm_calls is not None:
            out["max_llm_calls"] = self.llm_calls
        if self.tokens is not None:
            out["max_episode_tokens"] = self.tokens
        if self.usd is not None:
            out["max_episode_cost_usd"] = self.usd
        return out


class RaySpec(StrictModel):
    """The ``ray:`` section: the cluster to join (``address``; None: start a local Ray unless the
    command line names one), the resources of a Ray started here, and the CPU share of each episode
    worker."""

    address: Annotated[str, Field(max_length=NAME_MAX), AfterValidator(check_ray_address)] | None = None
    num_cpus: Annotated[int, NOT_BOOL, Bounded("ray.num_cpus")] | None = None
    dashboard: bool = False
    object_store_mb: Annotated[int, NOT_BOOL, Bounded("ray.object_store_mb")] = 256
    #: CPU share of one episode worker actor (small: workers wait on the model)
    worker_cpus: Annotated[float, NOT_BOOL, Bounded("ray.worker_cpus")] = 0.05
    #: coding sweeps: at most this many episode workers (each with its sandbox container, and its
    #: evaluation's while it judges a submission) on one node. A Ray started here declares the
    #: node resource ``recap_sandbox`` = N; the nodes of an existing cluster must declare it
    #: themselves (``ray start --resources '{"recap_sandbox": N}'``, cluster.yaml)
    sandboxes_per_node: Annotated[int, NOT_BOOL, Bounded("ray.sandboxes_per_node")] | None = None
    #: episodes one worker process plays at once, each on its own thread with its own environment
    #: and agent (a Ray worker process costs ~50 MB before it plays anything). None ("auto"): one
    #: while the workers fit in 4 processes per CPU, more beyond (2 CPUs: 32 workers, 4 per
    #: process; :func:`pipeline.worker_pool.episodes_per_process`). Always one for a sandboxed
    #: benchmark with ray.sandboxes_per_node (a worker holds its node's sandbox slot)
    episodes_per_process: Annotated[int, NOT_BOOL, Bounded("ray.episodes_per_process")] | None = None


class SweepSpec(StrictModel):
    """A validated sweep file: models x methods x environments x sampling seeds make the units;
    limits, caps, attempts, start order and Ray settings say how they run. Unknown keys are errors.

    ``sampling_seeds`` was called ``seeds`` before: the old key still reads (sweep files and the
    ``spec.yaml`` of run folders written then), both at once is refused."""

    run: Annotated[str, Field(max_length=NAME_MAX)]
    output: Annotated[str, Field(min_length=1, max_length=PATH_MAX)]
    models: list[ModelSpec] = Field(min_length=1, max_length=LIST_MAX)
    methods: list[MethodSpec] = Field(min_length=1, max_length=LIST_MAX)
    environments: list[EnvSpec] = Field(min_length=1, max_length=LIST_MAX)
    #: the units' sampling seeds: each one is its own unit (repetitions of one instance); an
    #: error names the key the file used (``seeds[0]: ...`` under the old name)
    sampling_seeds: list[Annotated[int, NOT_BOOL, Bounded("sampling_seeds[]")]] = Field(
        default_factory=lambda: [0],
        min_length=1,
        max_length=SAMPLING_SEEDS_MAX,
        validation_alias=AliasChoices("sampling_seeds", OLD_SEEDS_KEY),
    )
    step_multiplier: Annotated[float, NOT_BOOL, Bounded("step_multiplier")] = 4.0
    limits: LimitsSpec = Field(default_factory=LimitsSpec)
    run_cap_usd: Annotated[float, NOT_BOOL, Bounded("run_cap_usd")] | None = None
    workers: Annotated[int, NOT_BOOL, Bounded("workers")] = 4
    max_attempts: Annotated[int, NOT_BOOL, Bounded("max_attempts")] = 3
    #: the order units start in (not part of any unit hash): ``interleaved`` (default) takes the
    #: arms (method x model) in turn and, within an arm, instances in a shuffle seeded by the run
    #: name, so a cap that binds early leaves a balanced subsample; ``plan`` is the plan's own
    #: order (instances, then methods, models, sampling seeds). See :func:`pipeline.units.order_units`.
    order: Literal["interleaved", "plan"] = "interleaved"
    ray: RaySpec = Field(default_factory=RaySpec)

    @field_validator("sampling_seeds")
    @classmethod
    def _distinct_seeds(cls, v: list[int]) -> list[int]:
        """Named by the key the file used (``seeds: repeated seed`` under the old name)."""
        if len(set(v)) != len(v):
            raise ValueError("repeated seed")
        return v

    @model_validator(mode="before")
    @classmethod
    def _one_seeds_key(cls, data: Any) -> Any:
        """The old key and the new one together would leave one of them silently unused."""
        if isinstance(data, dict) and OLD_SEEDS_KEY in data and "sampling_seeds" in data:
            raise ValueError(f"give sampling_seeds or its old name {OLD_SEEDS_KEY}, not both")
        return data

    @field_validator("run")
    @classmethod
    def _run_name(cls, v: str) -> str:
        if not RUN_NAME.match(v):
            raise ValueError("must be letters, digits, '.', '_' or '-' (starting with a letter or digit)")
        return v

    @field_validator("output")
    @classmethod
    def _output(cls, v: str) -> str:
        """Resolved once: every component (store, sink, gateway, mirror) sees this string."""
        printable(v)
        if not is_uri(v):
            return local_path(v)
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
