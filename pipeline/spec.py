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
        prices: {input: 2.5, output: 10, cached_input: 1.25}   # USD per million tokens
        cap_usd: 2.0                  # per-model dollar cap
    methods:
      - method: recap
        profile: paper
        ablation: no_think
        settings: {window: 64}
      - method: react
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
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from pipeline.errors import SpecError

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]*$")

#: models served in-process by the gateway's test-double provider (no key, no real spend)
OFFLINE_PREFIX = "offline/"


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class PriceSpec(_Strict):
    """USD per million tokens; ``cached_input`` defaults to ``input``."""

    input: float = Field(ge=0)
    output: float = Field(ge=0)
    cached_input: float | None = Field(default=None, ge=0)


class ModelSpec(_Strict):
    model: str = Field(min_length=1)
    label: str | None = None
    #: sent with every call (temperature override, top_p, provider options, test-double knobs)
    params: dict[str, Any] = Field(default_factory=dict)
    #: knobs of the offline/ test doubles (seed, invalid_action_rate, malformed_json_rate,
    #: chunk_size); part of the unit hash
    options: dict[str, Any] = Field(default_factory=dict)
    # --- transport: never part of a unit's identity ---
    rpm: int | None = Field(default=None, gt=0)
    tpm: int | None = Field(default=None, gt=0)
    concurrency: int | None = Field(default=None, gt=0)
    #: the quota window rpm/tpm count over (60 s for real providers; shorter for test servers)
    window_s: float | None = Field(default=None, gt=0)
    retries: int | None = Field(default=None, ge=0)
    timeout_s: float | None = Field(default=None, gt=0)
    prices: PriceSpec | None = None
    api_base: str | None = None
    api_key_env: str | None = None
    cap_usd: float | None = Field(default=None, ge=0)

    @property
    def name(self) -> str:
        return self.label or self.model

    @property
    def test_double(self) -> bool:
        return self.model.startswith(OFFLINE_PREFIX)

    @field_validator("label")
    @classmethod
    def _label(cls, v: str | None) -> str | None:
        if v is not None and not v.strip():
            raise ValueError("must not be empty")
        return v

    @model_validator(mode="after")
    def _api_base_url(self) -> "ModelSpec":
        """A provider's base URL must be one (a typo would fail every call of the night);
        ``offline/replay`` takes a run folder there instead."""
        if self.api_base is not None and not self.test_double:
            from urllib.parse import urlparse

            url = urlparse(self.api_base)
            if url.scheme not in ("http", "https") or not url.netloc:
                raise ValueError(f"api_base: must be an http(s) URL such as http://127.0.0.1:8000/v1, got {self.api_base!r}")
        return self


class MethodSpec(_Strict):
    method: str = Field(min_length=1)
    label: str | None = None
    profile: str | None = None
    ablation: str | None = None
    settings: dict[str, Any] = Field(default_factory=dict)

    @property
    def name(self) -> str:
        if self.label:
            return self.label
        suffix = [x for x in (self.profile, None if self.ablation in (None, "original") else self.ablation) if x]
        return self.method + (f"[{','.join(suffix)}]" if suffix else "")


class EnvSpec(_Strict):
    benchmark: str = Field(min_length=1)
    #: selectors handed to the benchmark's list_instances (split, task, task type...)
    tasks: list[str] = Field(default_factory=list)
    #: explicit instance ids
    instances: list[str] = Field(default_factory=list)
    #: at most this many instances per selector (in the benchmark's fixed order)
    limit: int | None = Field(default=None, gt=0)
    #: options for the benchmark's make() (data_dir ...); not part of the unit hash
    options: dict[str, Any] = Field(default_factory=dict)


class LimitsSpec(_Strict):
    """Per-episode limits, mapped onto AgentConfig max_llm_calls / max_episode_tokens /
    max_episode_cost_usd (a method's own settings win)."""

    llm_calls: int | None = Field(default=None, gt=0)
    tokens: int | None = Field(default=None, gt=0)
    usd: float | None = Field(default=None, gt=0)

    def agent_settings(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        if self.llm_calls is not None:
            out["max_llm_calls"] = self.llm_calls
        if self.tokens is not None:
            out["max_episode_tokens"] = self.tokens
        if self.usd is not None:
            out["max_episode_cost_usd"] = self.usd
        return out


class RaySpec(_Strict):
    address: str | None = None
    num_cpus: int | None = Field(default=None, gt=0)
    dashboard: bool = False
    object_store_mb: int = Field(default=256, ge=64)
    #: CPU share of one episode worker actor (small: workers wait on the model)
    worker_cpus: float = Field(default=0.05, ge=0)


class SweepSpec(_Strict):
    run: str
    output: str = Field(min_length=1)
    models: list[ModelSpec] = Field(min_length=1)
    methods: list[MethodSpec] = Field(min_length=1)
    environments: list[EnvSpec] = Field(min_length=1)
    seeds: list[int] = Field(default_factory=lambda: [0], min_length=1)
    step_multiplier: float = Field(default=4.0, gt=0)
    limits: LimitsSpec = Field(default_factory=LimitsSpec)
    run_cap_usd: float | None = Field(default=None, ge=0)
    workers: int = Field(default=4, gt=0)
    max_attempts: int = Field(default=3, gt=0)
    ray: RaySpec = Field(default_factory=RaySpec)

    @field_validator("run")
    @classmethod
    def _run_name(cls, v: str) -> str:
        if not _NAME.match(v):
            raise ValueError("must be letters, digits, '.', '_' or '-' (starting with a letter or digit)")
        return v

    @model_validator(mode="after")
    def _unique(self) -> "SweepSpec":
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
    loc = _loc(tuple(first.get("loc", ())))
    msg = first.get("msg", "invalid")
    if first.get("type") == "extra_forbidden":
        msg = "unknown field"
    elif first.get("type") == "missing":
        msg = "required field is missing"
    msg = msg.removeprefix("Value error, ")
    more = f" (and {len(errors) - 1} more problem{'s' if len(errors) > 2 else ''})" if len(errors) > 1 else ""
    return f"{source}: {loc + ': ' if loc else ''}{msg}{more}"


def parse_spec(text: str, source: str = "spec") -> SweepSpec:
    """Parse and validate YAML text; every problem is one :class:`SpecError` line."""
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise SpecError(f"{source}: malformed YAML{where}: {problem}") from None
    if not isinstance(data, dict):
        raise SpecError(f"{source}: the sweep file must be a YAML mapping (run:, output:, models:, ...)")
    try:
        return SweepSpec.model_validate(data)
    except ValidationError as exc:
        raise SpecError(_pydantic_message(source, exc)) from None


def load_spec(path: str | Path) -> tuple[SweepSpec, str]:
    """(validated spec, its YAML text) from a file."""
    p = Path(path)
    try:
        text = p.read_text()
    except FileNotFoundError:
        raise SpecError(f"sweep file {str(p)!r} does not exist") from None
    except (IsADirectoryError, UnicodeDecodeError) as exc:
        raise SpecError(f"sweep file {str(p)!r} cannot be read: {exc}") from None
    return parse_spec(text, p.name), text


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
    return hashlib.sha256(text.encode()).hexdigest()[:16]
