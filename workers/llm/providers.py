"""One provider deployment: which model, where, with which key, under which limits.

Why a model of its own: the pipeline builds these from the sweep spec, the gateway enforces
them, and the direct client uses the same fields, so the three agree on what a deployment
is. The API key itself is never stored: only the *name* of the environment variable holding
it, read at call time, so no config, record or log line can carry a key.
"""

from __future__ import annotations

import base64
import functools
import os
from collections.abc import Mapping, Sequence
from typing import Any, Literal
from urllib.parse import parse_qsl, unquote, urlencode, urlsplit, urlunsplit

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from schemas.ranges import range_problem
from workers.llm.pricing import Price, PriceTable, default_prices, resolve_price

#: generation settings passed through to litellm (anything else is refused: typos surface)
ALLOWED_PARAMS = frozenset(
    {
        "temperature",
        "max_tokens",
        "top_p",
        "seed",
        "stop",
        "presence_penalty",
        "frequency_penalty",
        "response_format",
        "n",
        "logit_bias",
    }
)
#: params that multiply the output a provider generates and bills (choices per call). Agents
#: read one choice and the budget reserves one, so any value but 1 is refused at config time.
SINGLE_CHOICE_PARAMS = ("n", "best_of")
DEFAULT_MAX_TOKENS = 1024
OFFLINE_PREFIX = "offline/"


#: our ceiling for ``max_tokens`` (2**18): above every model's output limit in litellm's map but a
#: few outliers; the preflight also holds a model to its own limit (litellm's max_output_tokens)
MAX_TOKENS_CEILING = 262_144
#: the largest ``|bias|`` a logit_bias entry may carry (OpenAI's range) and the most entries
LOGIT_BIAS_MAX = 100.0
LOGIT_BIAS_ENTRIES_MAX = 1000

#: numeric generation params: (integer only, lowest, highest), both ends inclusive; a wrong
#: value would be refused by the provider on every call of a run (or, for max_tokens, lowered
#: to the method's own cap without a word), so it is refused here, before the first call, with
#: its range in the message. Every numeric param in ALLOWED_PARAMS has an entry (tests check).
NUMERIC_PARAMS: dict[str, tuple[bool, float, float]] = {
    "temperature": (False, 0.0, 2.0),
    "top_p": (False, 0.0, 1.0),
    "max_tokens": (True, 1, MAX_TOKENS_CEILING),
    "n": (True, 1, 1),
    "seed": (True, 0, 2**63 - 1),
    "presence_penalty": (False, -2.0, 2.0),
    "frequency_penalty": (False, -2.0, 2.0),
}


def _param_problem(name: str, value: Any) -> str | None:
    """What is wrong with one generation param's value (None when nothing is)."""
    if name in SINGLE_CHOICE_PARAMS and (isinstance(value, bool) or value != 1):
        return (
            "must be 1: the gateway sends one choice per call (agents read one, and the budget "
            "reserves the worst case of one); leave it out"
        )
    if name in NUMERIC_PARAMS:
        return range_problem(value, *NUMERIC_PARAMS[name])
    if name == "logit_bias":
        if not isinstance(value, Mapping) or len(value) > LOGIT_BIAS_ENTRIES_MAX:
            return f"must be a mapping of token id -> bias with at most {LOGIT_BIAS_ENTRIES_MAX} entries"
        for token, bias in value.items():
            problem = range_problem(bias, False, -LOGIT_BIAS_MAX, LOGIT_BIAS_MAX)
            if problem:
                return f"entry {token!r}: {problem}"
    if name == "stop" and not (isinstance(value, str) or (isinstance(value, list) and all(isinstance(x, str) for x in value))):
        return "must be a string or a list of strings"
    return None


#: query parameters of a base URL that carry credentials (dropped from every displayed name)
SECRET_QUERY_PARAMS = frozenset(
    {
        "key",
        "api_key",
        "apikey",
        "api-key",
        "token",
        "access_token",
        "auth",
        "auth_token",
        "secret",
        "password",
        "sig",
        "signature",
        "code",
    }
)


def _is_secret_param(name: str) -> bool:
    n = name.lower()
    return n in SECRET_QUERY_PARAMS or n.endswith(("_key", "-key", "_token", "-token", "secret", "password"))


def redact_url(url: str) -> str:
    """``url`` without credentials: no ``user:password@`` and no ``key=``/``api_key=``/``token=``
    (...) query parameters. Used for every name, record and log line that shows a base URL;
    the provider still gets the real URL. A URL without credentials comes back unchanged."""
    try:
        parts = urlsplit(url)
    except ValueError:
        return "[unparseable api_base]"
    netloc = parts.netloc
    if "@" in netloc:
        netloc = netloc.rsplit("@", 1)[1]
    query = parts.query
    if query:
        pairs = parse_qsl(query, keep_blank_values=True)
        kept = [(k, v) for k, v in pairs if not _is_secret_param(k)]
        if len(kept) != len(pairs):
            query = urlencode(kept)
    if netloc == parts.netloc and query == parts.query:
        return url
    return urlunsplit((parts.scheme, netloc, parts.path, query, parts.fragment))


def url_secrets(url: str | None) -> list[str]:
    """The credentials inside a base URL, in every form a reply or an error could echo them:
    the password, ``user:password`` (raw and percent-decoded), its HTTP Basic base64 form, a
    lone user name (a token), and the values of credential query parameters."""
    if not url:
        return []
    try:
        parts = urlsplit(url)
    except ValueError:
        return []
    out: list[str] = []
    if "@" in parts.netloc:
        userinfo = parts.netloc.rsplit("@", 1)[0]
        user, has_password, password = userinfo.partition(":")
        for raw in (userinfo, unquote(userinfo)):
            out.append(raw)
            out.append(base64.b64encode(raw.encode()).decode())
        if has_password:
            out += [password, unquote(password)]
        else:
            out += [user, unquote(user)]
    for k, v in parse_qsl(parts.query, keep_blank_values=True):
        if _is_secret_param(k) and v:
            out += [v, unquote(v)]
    return sorted({s for s in out if s and len(s) >= 4}, key=len, reverse=True)


class QueueSource(BaseModel):
    """Where the gateway reads how many requests a served model's replicas hold waiting (the
    queue figure its in-flight limit adapts to: :mod:`workers.gateway.queue_feed`, read by
    :mod:`workers.serving.queue_source`). Set by the sweep's serving (pipeline.serving), per engine:

    * ``replica_metrics``: each replica of Serve application ``app`` answers its engine's
      Prometheus text (the test double: vLLM's gauge); ``gauges`` summed over the replicas;
    * ``replica_ongoing``: Serve's own count of each replica's requests, less the ``running``
      its engine runs at once (llama.cpp's server runs one, exposes no metrics);
    * ``ray_metrics``: the engine's gauges as Ray's metrics agents export them on every node
      (vLLM / SGLang under ``ray.serve.llm``), the samples whose labels match ``labels``.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    kind: Literal["replica_metrics", "replica_ongoing", "ray_metrics"]
    app: str
    gauges: tuple[str, ...] = ()
    labels: dict[str, str] = Field(default_factory=dict)
    running: int = Field(default=1, ge=0)
    #: seconds between two reads while calls are in flight
    period_s: float = Field(default=1.0, gt=0)


class DeploymentConfigError(ValueError):
    """A deployment configuration that cannot work."""


class DeploymentConfig(BaseModel):
    """A provider deployment (model + base URL + key) and its limits.

    ``rpm``/``tpm`` are the provider's quota for this deployment per ``window_s`` (60 s for real
    providers; tests scale it down). ``max_concurrency`` is the in-flight limit that the
    gateway halves on HTTP 429 and grows back additively. Retries: at most ``max_attempts``
    attempts, all within ``total_timeout_s``, each cut at ``attempt_timeout_s``.
    ``params`` are generation settings (``temperature``, ``max_tokens``, ...); a request's own
    temperature / max_tokens take precedence, capped at ``params['max_tokens']``.
    ``price`` overrides the repo price table for this model.
    ``offline_options`` configures the ``offline/`` test doubles (noise_seed, invalid_action_rate,
    malformed_json_rate, chunk_size); ignored for real providers.
    ``cache_markers``: mark prompt-cache breakpoints (:mod:`workers.llm.cache_markers`) on the
    messages sent; None: when the model's price says its provider caches only at explicit
    breakpoints (``explicit_cache``), False turns the markers off.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    model: str
    api_base: str | None = None
    api_key_env: str | None = None
    name: str | None = None
    rpm: int | None = Field(default=None, gt=0)
    tpm: int | None = Field(default=None, gt=0)
    window_s: float = Field(default=60.0, gt=0)
    #: extra seconds added to the client-side window (provider clock granularity)
    window_pad_s: float = Field(default=0.25, ge=0)
    #: "response": a request counts until window_s after its response (safe whatever the
    #: delays); "admission": for window_s after it was admitted (pad must cover send delays)
    window_anchor: Literal["response", "admission"] = "response"
    max_concurrency: int = Field(default=16, gt=0)
    #: set (a served model: pipeline.serving): the in-flight limit adapts to the server's latency
    #: and capacity errors between this floor and ``max_concurrency`` (workers.gateway.adaptive)
    min_concurrency: int | None = Field(default=None, gt=0)
    #: set (a served model): where the gateway reads the replicas' waiting requests, which the
    #: in-flight limit adapts to as well (workers.gateway.queue_feed)
    queue_source: QueueSource | None = None
    max_attempts: int = Field(default=6, gt=0)
    total_timeout_s: float = Field(default=900.0, gt=0)
    attempt_timeout_s: float = Field(default=120.0, gt=0)
    #: exponential backoff between attempts after 5xx / timeouts (seconds)
    backoff_initial_s: float = Field(default=1.0, ge=0)
    backoff_max_s: float = Field(default=30.0, ge=0)
    #: wait after a 429 that carried no Retry-After header
    rate_limit_default_wait_s: float = Field(default=5.0, ge=0)
    #: the longest Retry-After the gateway honours: a 429 asking for more fails the call at
    #: once as ``LLMError("rate_limit")`` (and does not pause the deployment) instead of sleeping
    max_retry_after_s: float = Field(default=120.0, ge=0)
    #: replies whose usage is rejected as impossible (each charged at its worst case) after which
    #: the gateway refuses this deployment's further calls for the session (a ``usage`` refusal:
    #: the driver stops starting the model's units, the other models go on)
    max_usage_rejections: int = Field(default=3, gt=0)
    params: dict[str, Any] = Field(default_factory=dict)
    price: Price | None = None
    #: serve identical requests (model, params, messages) from the ledger's response cache
    cache: bool = False
    #: None: inferred (offline/ models and price-table test doubles are test doubles)
    test_double: bool | None = None
    offline_options: dict[str, Any] = Field(default_factory=dict)
    cache_markers: bool | None = None

    @field_validator("model")
    @classmethod
    def _model_named(cls, v: str) -> str:
        if not v or v.strip() != v:
            raise ValueError(f"model must be a non-empty provider string, got {v!r}")
        return v

    @field_validator("params")
    @classmethod
    def _known_params(cls, v: dict[str, Any]) -> dict[str, Any]:
        for name in SINGLE_CHOICE_PARAMS:  # before the unknown check: best_of gets this message too
            if name in v and (isinstance(v[name], bool) or v[name] != 1):
                raise ValueError(f"{name} {_param_problem(name, v[name])}, got {v[name]!r}")
        unknown = set(v) - ALLOWED_PARAMS
        if unknown:
            raise ValueError(f"unknown generation param(s) {sorted(unknown)}; allowed: {sorted(ALLOWED_PARAMS)}")
        for name, value in v.items():
            problem = _param_problem(name, value)
            if problem:
                raise ValueError(f"{name} {problem}")
        return v

    @field_validator("price", mode="before")
    @classmethod
    def _price(cls, v: Any) -> Any:
        if isinstance(v, Mapping):
            return Price.from_mapping(v, "deployment price override")
        return v

    @model_validator(mode="after")
    def _api_base_scheme(self) -> DeploymentConfig:
        if self.model == "offline/replay" and not self.api_base:
            raise ValueError("offline/replay needs api_base = the run folder to replay")
        return self

    def __repr_args__(self) -> Any:  # reprs and validation errors never show URL credentials
        for name, value in super().__repr_args__():
            yield name, (redact_url(value) if name == "api_base" and isinstance(value, str) else value)

    # ---- derived ----
    @property
    def display_api_base(self) -> str | None:
        """The base URL without credentials (what names, records and logs show)."""
        return None if self.api_base is None else redact_url(self.api_base)

    @property
    def deployment_name(self) -> str:
        """Stable id of the deployment (model + base URL without credentials + key *name*),
        used in records, file names and the ledger."""
        if self.name:
            return self.name
        parts = [self.model]
        if self.api_base:
            parts.append(f"@{self.display_api_base}")
        if self.api_key_env:
            parts.append(f"#{self.api_key_env}")
        return "".join(parts)

    @property
    def is_offline(self) -> bool:
        return self.model.startswith(OFFLINE_PREFIX)

    @property
    def max_output_tokens(self) -> int:
        return int(self.params.get("max_tokens") or DEFAULT_MAX_TOKENS)

    def resolved_price(self, table: PriceTable | None = None) -> Price | None:
        return resolve_price(self.model, self.price, table)

    def uses_cache_markers(self, table: PriceTable | None = None) -> bool:
        """Whether the gateway marks cache breakpoints on this deployment's requests."""
        if self.cache_markers is not None:
            return self.cache_markers
        if self.is_offline:
            return False
        price = self.resolved_price(table)
        return bool(price and price.explicit_cache)

    def is_test_double(self, table: PriceTable | None = None) -> bool:
        if self.test_double is not None:
            return self.test_double
        if self.is_offline:
            return True
        price = resolve_price(self.model, None, table or default_prices())
        return bool(price and price.test_double)

    def secrets(self) -> list[str]:
        """Every secret value of this deployment (the API key, if set, and the base URL's
        credentials), longest first: what redaction removes from stored and returned text."""
        out = url_secrets(self.api_base)
        if self.api_key_env:
            key = os.environ.get(self.api_key_env)
            if key and len(key) >= 4:
                out.append(key)
        return sorted(set(out), key=len, reverse=True)

    def api_key(self) -> str | None:
        """The key, read from the environment now (never stored)."""
        if not self.api_key_env:
            return None
        key = os.environ.get(self.api_key_env)
        if not key:
            raise DeploymentConfigError(f"environment variable {self.api_key_env} (API key of {self.model}) is not set")
        return key

    def generation_params(self, temperature: float | None, max_tokens: int | None, json_mode: bool) -> dict[str, Any]:
        """The settings one request is sent with; max_tokens always set (bounds the cost).

        A request without its own cap (``max_tokens`` None: the ``paper`` and ``released``
        profiles, which used the provider's default) gets the model's whole output
        (:func:`model_max_output_tokens`), so no reply the provider would have finished is cut
        by us; a model litellm does not know gets DEFAULT_MAX_TOKENS (set ``params: {max_tokens:
        N}`` on the model for another bound)."""
        params = dict(self.params)
        if temperature is not None:
            params["temperature"] = temperature
        if "max_tokens" in self.params and self.params["max_tokens"]:
            # the user's own cap for this model bounds every request (and the budget's worst case)
            cap = int(self.params["max_tokens"])
            params["max_tokens"] = min(int(max_tokens), cap) if max_tokens else cap
        elif max_tokens:
            # otherwise the method's measured need (AgentConfig.max_tokens) is sent as is
            params["max_tokens"] = int(max_tokens)
        else:
            params["max_tokens"] = (None if self.is_offline else model_max_output_tokens(self.model)) or DEFAULT_MAX_TOKENS
        if json_mode and "response_format" not in params:
            params["response_format"] = {"type": "json_object"}
        return params

    def schema_params(self, schema: Mapping[str, Any] | None) -> dict[str, Any]:
        """The ``response_format`` for a request's reply schema (``LLMRequest.response_schema``):
        strict ``json_schema`` where the model supports it (as swebench-recap/sweagent/agent/
        models.py:707-731 sends it), ``json_object`` where it has only JSON mode, nothing where it
        has neither, for a test double, or when the model's own ``params`` set a response format."""
        if schema is None or "response_format" in self.params or self.is_offline:
            return {}
        support = response_format_support(self.model)
        if support == "json_schema":
            return {"response_format": {"type": "json_schema", "json_schema": {**schema, "strict": True}}}
        if support == "json_object":
            return {"response_format": {"type": "json_object"}}
        return {}


#: what a model accepts as a ``response_format`` (:func:`response_format_support`)
ResponseFormatSupport = Literal["json_schema", "json_object", "none"]


@functools.lru_cache(maxsize=256)
def response_format_support(model: str) -> ResponseFormatSupport:
    """How ``model`` can be held to a JSON reply, by litellm's model map: ``json_schema`` (strict
    structured output, ``litellm.supports_response_schema``), ``json_object`` (JSON mode only),
    or ``none`` (no ``response_format`` at all; the prompt alone asks for JSON)."""
    import litellm  # heavy (seconds): only when a schema is asked for

    try:
        if litellm.supports_response_schema(model=model):
            return "json_schema"
    except Exception:  # a model litellm does not know
        pass
    try:
        supported = litellm.get_supported_openai_params(model=model) or []
    except Exception:
        supported = []
    return "json_object" if "response_format" in supported else "none"


@functools.lru_cache(maxsize=256)
def model_max_output_tokens(model: str) -> int | None:
    """The most output tokens ``model`` can produce, from litellm's model map (the provider
    prefix is tried with and without: ``openai/gpt-4o-2024-08-06`` -> 16384); None when unknown."""
    import litellm  # heavy (seconds): only when a model's output limit is asked

    names = [model] + ([model.split("/", 1)[1]] if "/" in model else [])
    for name in names:
        value = (litellm.model_cost.get(name) or {}).get("max_output_tokens")
        if isinstance(value, int) and value > 0:
            return value
    return None


def provider_messages(messages: Sequence[Any]) -> list[dict[str, Any]]:
    """ChatMessage objects (or dicts) as the dicts a provider receives: role and content, plus an
    assistant message's ``tool_calls`` and a tool message's ``tool_call_id`` when present."""
    out: list[dict[str, Any]] = []
    for m in messages:
        if isinstance(m, Mapping):
            d: dict[str, Any] = {"role": str(m["role"]), "content": str(m["content"])}
            for key in ("tool_calls", "tool_call_id"):
                if m.get(key):
                    d[key] = m[key]
        else:
            d = {"role": m.role, "content": m.content}
            if getattr(m, "tool_calls", ()):
                d["tool_calls"] = [c.as_dict() for c in m.tool_calls]
            if getattr(m, "tool_call_id", None) is not None:
                d["tool_call_id"] = m.tool_call_id
        out.append(d)
    return out
