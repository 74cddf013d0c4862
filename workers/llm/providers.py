"""One provider deployment: which model, where, with which key, under which limits.

Why a model of its own: the pipeline builds these from the sweep spec, the gateway enforces
them, and the direct client uses the same fields, so the three agree on what a deployment
is. The API key itself is never stored: only the *name* of the environment variable holding
it, read at call time, so no config, record or log line can carry a key.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from workers.llm.pricing import Price, PriceTable, default_prices, resolve_price

#: generation settings passed through to litellm (anything else is refused: typos surface)
ALLOWED_PARAMS = frozenset(
    {"temperature", "max_tokens", "top_p", "seed", "stop", "presence_penalty",
     "frequency_penalty", "response_format", "n", "logit_bias"}
)
DEFAULT_MAX_TOKENS = 1024
OFFLINE_PREFIX = "offline/"


#: numeric generation params: (integer only, lowest, highest); a wrong value would be refused
#: by the provider on every call of a run, so it is refused here, before the first
_NUMERIC_PARAMS: dict[str, tuple[bool, float | None, float | None]] = {
    "temperature": (False, 0.0, 2.0), "top_p": (False, 0.0, 1.0), "max_tokens": (True, 1, None),
    "n": (True, 1, None), "seed": (True, None, None),
    "presence_penalty": (False, -2.0, 2.0), "frequency_penalty": (False, -2.0, 2.0),
}


def _param_problem(name: str, value: Any) -> str | None:
    """What is wrong with one generation param's value (None when nothing is)."""
    if name in _NUMERIC_PARAMS:
        integer, low, high = _NUMERIC_PARAMS[name]
        kind = "an integer" if integer else "a number"
        if isinstance(value, bool) or not isinstance(value, int if integer else (int, float)):
            return f"must be {kind}"
        if (low is not None and value < low) or (high is not None and value > high):
            bounds = f">= {low}" if high is None else f"within [{low}, {high}]"
            return f"must be {kind} {bounds}"
    if name == "stop" and not (isinstance(value, str) or (isinstance(value, list) and all(isinstance(x, str) for x in value))):
        return "must be a string or a list of strings"
    return None


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
    ``offline_options`` configures the ``offline/`` test doubles (seed, invalid_action_rate,
    malformed_json_rate, chunk_size); ignored for real providers.
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
    max_attempts: int = Field(default=6, gt=0)
    total_timeout_s: float = Field(default=900.0, gt=0)
    attempt_timeout_s: float = Field(default=120.0, gt=0)
    #: exponential backoff between attempts after 5xx / timeouts (seconds)
    backoff_initial_s: float = Field(default=1.0, ge=0)
    backoff_max_s: float = Field(default=30.0, ge=0)
    #: wait after a 429 that carried no Retry-After header
    rate_limit_default_wait_s: float = Field(default=5.0, ge=0)
    params: dict[str, Any] = Field(default_factory=dict)
    price: Price | None = None
    #: serve identical requests (model, params, messages) from the ledger's response cache
    cache: bool = False
    #: None: inferred (offline/ models and price-table test doubles are test doubles)
    test_double: bool | None = None
    offline_options: dict[str, Any] = Field(default_factory=dict)

    @field_validator("model")
    @classmethod
    def _model_named(cls, v: str) -> str:
        if not v or v.strip() != v:
            raise ValueError(f"model must be a non-empty provider string, got {v!r}")
        return v

    @field_validator("params")
    @classmethod
    def _known_params(cls, v: dict[str, Any]) -> dict[str, Any]:
        unknown = set(v) - ALLOWED_PARAMS
        if unknown:
            raise ValueError(f"unknown generation param(s) {sorted(unknown)}; allowed: {sorted(ALLOWED_PARAMS)}")
        for name, value in v.items():
            problem = _param_problem(name, value)
            if problem:
                raise ValueError(f"{name} {problem}, got {value!r}")
        return v

    @field_validator("price", mode="before")
    @classmethod
    def _price(cls, v: Any) -> Any:
        if isinstance(v, Mapping):
            return Price.from_mapping(v, "deployment price override")
        return v

    @model_validator(mode="after")
    def _api_base_scheme(self) -> "DeploymentConfig":
        if self.model == "offline/replay" and not self.api_base:
            raise ValueError("offline/replay needs api_base = the run folder to replay")
        return self

    # ---- derived ----
    @property
    def deployment_name(self) -> str:
        """Stable id of the deployment (model + base URL + key *name*), used in records."""
        if self.name:
            return self.name
        parts = [self.model]
        if self.api_base:
            parts.append(f"@{self.api_base}")
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

    def is_test_double(self, table: PriceTable | None = None) -> bool:
        if self.test_double is not None:
            return self.test_double
        if self.is_offline:
            return True
        price = resolve_price(self.model, None, table or default_prices())
        return bool(price and price.test_double)

    def api_key(self) -> str | None:
        """The key, read from the environment now (never stored)."""
        if not self.api_key_env:
            return None
        key = os.environ.get(self.api_key_env)
        if not key:
            raise DeploymentConfigError(
                f"environment variable {self.api_key_env} (API key of {self.model}) is not set"
            )
        return key

    def generation_params(self, temperature: float | None, max_tokens: int | None,
                          json_mode: bool) -> dict[str, Any]:
        """The settings one request is sent with; max_tokens always set (bounds the cost)."""
        params = dict(self.params)
        if temperature is not None:
            params["temperature"] = temperature
        if "max_tokens" in self.params and self.params["max_tokens"]:
            # the user's own cap for this model bounds every request (and the budget's worst case)
            cap = int(self.params["max_tokens"])
            params["max_tokens"] = min(int(max_tokens), cap) if max_tokens else cap
        else:
            # otherwise the method's measured need (AgentConfig.max_tokens) is sent as is
            params["max_tokens"] = int(max_tokens) if max_tokens else DEFAULT_MAX_TOKENS
        if json_mode and "response_format" not in params:
            params["response_format"] = {"type": "json_object"}
        return params


def provider_messages(messages: Sequence[Any]) -> list[dict[str, str]]:
    """ChatMessage objects (or dicts) as the role/content dicts a provider receives."""
    out = []
    for m in messages:
        if isinstance(m, Mapping):
            out.append({"role": str(m["role"]), "content": str(m["content"])})
        else:
            out.append({"role": m.role, "content": m.content})
    return out
