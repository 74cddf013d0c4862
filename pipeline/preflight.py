"""Checks that must pass before a sweep spends anything: API keys present, prices known for
every model a dollar cap applies to (:func:`preflight`), and every unit able to start its
episode: data folder found, the method's demonstration renders for the task kind
(:func:`check_plan`).

Why before everything: a missing key discovered at the first call of the first episode would
turn a night's run into hundreds of ``auth`` failures; a cap on a model whose calls cannot be
priced cannot be enforced at all; a method whose demonstration cannot render for a task kind
would fail every attempt of every unit and be stored as a 0 % result. Each is reported as one
line, before any write.
"""

from __future__ import annotations

import difflib
import json
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from unittest import mock

from pipeline.deployments import deployment_config
from pipeline.errors import PreflightError, SpecError
from pipeline.litellm_files import provider_names, surely_unroutable
from pipeline.serving.checks import check_serving
from pipeline.spec import OFFLINE_PREFIX, ModelSpec, SweepSpec
from pipeline.units import Plan, Unit, stratum
from recap.agent import Agent, DemonstrationError
from recap.env import DataNotFoundError, Environment
from workers.envs import registry
from workers.episode_worker import agent_from_config, env_options_for
from workers.llm.litellm_import import import_litellm
from workers.llm.litellm_setup import get_litellm
from workers.llm.offline.provider import MODELS as OFFLINE_MODELS
from workers.llm.pricing import PriceError, require_prices
from workers.llm.providers import DEFAULT_MAX_TOKENS


def _litellm_missing_keys(m: ModelSpec) -> list[str]:
    litellm = get_litellm()
    try:
        info = litellm.validate_environment(model=m.model, api_base=m.api_base)
    except Exception:  # an unknown provider: litellm cannot say, the first call will
        return []
    if info.get("keys_in_environment", True):
        return []
    return [k for k in info.get("missing_keys", []) if k]


def key_variables(m: ModelSpec) -> list[str]:
    """Names of the environment variables holding a real model's credentials: ``api_key_env``,
    else the ones litellm expects for the provider (asked with an empty environment)."""
    if m.test_double or m.serve is not None:  # a served model's route is the sweep's own: no key
        return []
    if m.api_key_env:
        return [m.api_key_env]
    # litellm imported before the environment is emptied: its import sets TIKTOKEN_CACHE_DIR (the
    # bundled tokenizers), and a first import inside the patch would have that variable undone with
    # the rest on exit, leaving the process to count OpenAI prompts by the estimate from then on
    get_litellm()
    with mock.patch.dict(os.environ, {"LITELLM_LOCAL_MODEL_COST_MAP": "True"}, clear=True):
        return _litellm_missing_keys(m)


def check_keys(spec: SweepSpec) -> None:
    """Every real model's API key is set (its ``api_key_env``, else the variables litellm expects); test doubles
    need none. Raises PreflightError."""
    for i, m in enumerate(spec.models):
        if m.test_double or m.serve is not None:
            continue
        if m.api_key_env:
            if not os.environ.get(m.api_key_env):
                raise PreflightError(f"models[{i}] ({m.name}): API key variable {m.api_key_env} is not set")
            continue
        missing = _litellm_missing_keys(m)
        if missing:
            raise PreflightError(
                f"models[{i}] ({m.name}): API key missing: set {' or '.join(missing)} (or name another variable with api_key_env)"
            )


# --------------------------------------------------------------------------------------------
# the models: a provider litellm knows, params within range, an output cap the model has
# --------------------------------------------------------------------------------------------
def _providers() -> list[str]:
    """The provider prefixes litellm routes (``openai``, ``together_ai``, ...)."""
    return sorted({str(getattr(p, "value", p)) for p in import_litellm().provider_list})


def provider_problem(m: ModelSpec) -> str | None:
    """Why no call of model entry ``m`` could reach a provider (None when one can): an unknown
    provider prefix (``nosuchprovider/zzz``), a model without a prefix litellm does not know
    (``zzz``), or an ``offline/`` name that is not one of the test doubles. Asked of litellm the
    way a call asks it (``get_llm_provider``), so ``gpt-4o`` and ``openai/<anything>`` at an
    ``api_base`` (a self-hosted server) pass. A known provider prefix, and a model string no route
    of litellm's can take, are answered from litellm's files without importing it
    (:mod:`pipeline.litellm_files`): a refused sweep file costs no litellm import."""
    if m.test_double:
        name = m.model.removeprefix(OFFLINE_PREFIX)
        if name in OFFLINE_MODELS:
            return None
        return f"unknown test double {m.model!r}; known: {', '.join(OFFLINE_PREFIX + x for x in OFFLINE_MODELS)}"
    prefix, slash, rest = m.model.partition("/")
    names = provider_names()
    offline = frozenset({OFFLINE_PREFIX.rstrip("/")})
    if slash and names is not None and prefix in names:
        return None  # a provider of litellm's: routed, or known and in need of its settings (check_keys)
    if names is not None and surely_unroutable(m.model, m.api_base, offline):
        known = sorted(names)  # litellm's answer, read from its files: refused without importing it
    else:
        try:
            import_litellm().get_llm_provider(m.model, api_base=m.api_base)
            return None
        except Exception:
            pass
        known = _providers()
    if not slash:
        return (
            f"litellm does not know the model {m.model!r} and it names no provider; write provider/model "
            f"(openai/{m.model} for an OpenAI-compatible server at api_base)"
        )
    if prefix in known:  # a known provider that needs more than the string (its settings: check_keys)
        return None
    lowered = {k.lower(): k for k in [*known, OFFLINE_PREFIX.rstrip("/")]}
    near = [lowered[x] for x in difflib.get_close_matches(prefix.lower(), list(lowered), n=3, cutoff=0.0)]
    return (
        f"unknown provider {prefix!r} in {m.model!r} (nearest known: {', '.join(near)}); "
        f"an OpenAI-compatible server at api_base is openai/{rest or '<model>'}"
    )


def model_output_limit(model: str) -> int | None:
    """The most output tokens ``model`` can produce per call by litellm's model map
    (``max_output_tokens``), None when the map does not say (self-hosted and unknown models)."""
    litellm = import_litellm()
    try:
        info = litellm.get_model_info(model)
    except Exception:
        return None
    limit = info.get("max_output_tokens") if isinstance(info, dict) else None
    return int(limit) if isinstance(limit, (int, float)) and not isinstance(limit, bool) and limit > 0 else None


def check_models(spec: SweepSpec) -> None:
    """Every model entry can be called as written, checked without a call and before anything is
    written (``recap run``, ``resume`` and ``estimate``): its provider is known
    (:func:`provider_problem`), its deployment config builds (generation params and test-double
    options within their ranges: :func:`pipeline.deployments.deployment_config`) and its
    ``params.max_tokens`` is within the model's own output limit (:func:`model_output_limit`):
    above it the provider would refuse every call. Raises SpecError (one line)."""
    for i, m in enumerate(spec.models):
        where = f"models[{i}] ({m.name})"
        problem = provider_problem(m)
        if problem:
            raise SpecError(f"{where}: {problem}")
        deployment_config(m, f"models[{i}]")
        cap = m.params.get("max_tokens")
        limit = None if m.test_double else model_output_limit(m.model)
        if isinstance(cap, int) and limit is not None and cap > limit:
            raise SpecError(
                f"{where}: params.max_tokens {cap} is above the model's output limit {limit} "
                f"(litellm's max_output_tokens for {m.model}); use at most {limit}"
            )


def check_output_caps(plan: Plan) -> None:
    """Every request of the plan asks for an output cap its model can give: a method's own
    ``max_tokens`` (ReCAP's 3072) above a model's output limit, with no ``params.max_tokens`` on
    the model to bound it, would be refused by the provider on every call. Raises SpecError."""
    spec = plan.spec
    seen: set[tuple[str, str]] = set()
    for u in plan.units:
        if (u.model_label, u.method_config) in seen:
            continue
        seen.add((u.model_label, u.method_config))
        i, m = next((i, m) for i, m in enumerate(spec.models) if m.name == u.model_label)
        if m.test_double or m.params.get("max_tokens"):
            continue  # a model cap bounds every request (and check_models held it to the limit)
        limit = model_output_limit(m.model)
        asked = json.loads(u.method_config).get("max_tokens") or DEFAULT_MAX_TOKENS
        if limit is not None and asked > limit:
            j = next((j for j, x in enumerate(spec.methods) if x.name == u.method_label), 0)
            raise SpecError(
                f"models[{i}] ({m.name}): methods[{j}] ({u.method_label}) asks for max_tokens {asked} but the model's "
                f"output limit is {limit} (litellm's max_output_tokens); give the model params: {{max_tokens: {limit}}}"
            )


def check_prices(spec: SweepSpec) -> None:
    """Every model under a cap (the run cap covers all models) must have a price."""
    for i, m in enumerate(spec.models):
        if spec.run_cap_usd is None and m.cap_usd is None:
            continue
        prices = m.token_prices()
        overrides = {m.model: prices} if prices is not None else None
        try:
            require_prices([m.model], overrides)
        except PriceError as exc:
            which = "run cap" if m.cap_usd is None else "model cap"
            raise PreflightError(f"models[{i}] ({m.name}) has a {which} but no price: {exc}") from None


def preflight(spec: SweepSpec) -> None:
    """The checks of a sweep before it may spend (the models, prices, then keys); raises
    SpecError or PreflightError on the first failure."""
    check_models(spec)
    check_prices(spec)
    check_serving(spec)
    check_keys(spec)


# --------------------------------------------------------------------------------------------
# the plan: every (benchmark, task kind, method configuration) can start an episode
# --------------------------------------------------------------------------------------------
#: longest message :func:`check_plan` raises (the CLI adds the sweep file's name in front)
MESSAGE_MAX = 280


def _clip(text: str, room: int) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= room else text[: max(room - 3, 0)].rstrip() + "..."


def _fit(head: str, reason: str, tail: str = "") -> str:
    """``head + reason + tail`` with ``reason`` shortened so the whole is at most MESSAGE_MAX."""
    return head + _clip(reason, MESSAGE_MAX - len(head) - len(tail)) + tail


def _reason(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    if isinstance(exc, DemonstrationError) and text:
        return text
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _canonical(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)


def _env_index(spec: SweepSpec, benchmark: str, options: Mapping[str, Any] | None) -> int:
    """The ``environments[]`` entry a unit's benchmark and options came from (for the message)."""
    same = [i for i, e in enumerate(spec.environments) if e.benchmark == benchmark]
    for i in same:
        if dict(spec.environments[i].options) == dict(options or {}):
            return i
    return same[0] if same else 0


def _data_error(spec: SweepSpec, u: Unit, exc: BaseException) -> SpecError:
    """A unit's benchmark cannot find its data: the line names the entry and the fix."""
    b = u.benchmark
    head = f"environments[{_env_index(spec, b, u.env_options)}] ({b}): cannot find its data: "
    reason = " ".join(str(exc).split())
    tail = "; `recap data list` shows where it looks"
    if "recap data fetch" not in reason:
        tail += f", `recap data fetch {b}` gets it"
    if len(head) + len(reason) + len(tail) > MESSAGE_MAX:  # the folders looked in: recap data list shows them
        reason = re.sub(r"\s*\(looked in .*\)$", "", reason)
    return SpecError(_fit(head, reason, tail))


def _check_refusal(spec: SweepSpec, u: Unit) -> None:
    """A benchmark that refuses a method (FEVER: ADaPT, "--" in the paper) says why in one line."""
    refusal = registry.get_benchmark(u.benchmark).refuses_method(u.method)
    if refusal is not None:
        i = next((k for k, m in enumerate(spec.methods) if m.name == u.method_label), None)
        raise SpecError(_fit(f"methods[{i}] ({u.method_label}) cannot run on {u.benchmark}: ", refusal))


def _local_folder(output: str) -> Path | None:
    """The run folder ``output`` names on this machine (a path or ``file://``), or None (an object store)."""
    if output.lower().startswith("file://"):
        return Path(output[len("file://") :])
    return None if "://" in output else Path(output)


def check_benchmarks(plan: Plan, needs: list[str] | None = None) -> set[tuple[str, str]]:
    """Each benchmark's own check of all its instances at once (:meth:`Benchmark.preflight`), per
    ``environments[]`` entry (its options); SpecError (one line) naming the entry otherwise.

    With ``needs`` (``recap estimate``), what an entry still needs on this machine
    (:meth:`Benchmark.run_needs`: images, a daemon) is added to it, prefixed with the entry,
    instead of refusing; returns the (benchmark, canonical options) of those entries, whose
    environments cannot be opened here."""
    groups: dict[tuple[str, str], list[Unit]] = {}
    for u in plan.units:
        groups.setdefault((u.benchmark, _canonical(u.env_options)), []).append(u)
    run_folder = _local_folder(plan.spec.output)
    lacking: set[tuple[str, str]] = set()
    for (bench, canon), units in groups.items():
        ids = list(dict.fromkeys(u.instance_id for u in units))
        benchmark, options = registry.get_benchmark(bench), dict(units[0].env_options or {})
        if needs is not None:
            missing = benchmark.run_needs(ids, options)
            if missing:
                where = f"environments[{_env_index(plan.spec, bench, units[0].env_options)}] ({bench})"
                needs.extend(f"{where}: {m}" for m in missing)
                lacking.add((bench, canon))
                continue
        refusal = benchmark.preflight(ids, options)
        if refusal is None and run_folder is not None:
            refusal = benchmark.refuses_run_folder(options, run_folder)
        if refusal is not None:
            head = f"environments[{_env_index(plan.spec, bench, units[0].env_options)}] ({bench}): "
            raise SpecError(_fit(head, refusal))
    return lacking


@dataclass
class _EnvProbe:
    """One environment to open (its first unit and make() options) and the agents to try on it."""

    unit: Unit
    options: dict[str, Any]
    methods: list[tuple[Unit, Agent]] = field(default_factory=list)


def _env_probes(plan: Plan) -> list[_EnvProbe]:
    """The plan's units grouped: one environment per (task kind, options, step multiplier),
    each with the (unit, agent) of every method configuration that runs on it."""
    agents: dict[tuple[str, str, str], Agent] = {}
    envs: dict[tuple[str, str, float], _EnvProbe] = {}
    seen: set[tuple[str, str, str, str, float]] = set()
    for u in plan.units:
        kind = stratum(u.instance_id)
        pre = (kind, u.method, u.method_config, _canonical(u.env_options), float(u.step_multiplier))
        if pre in seen:
            continue
        seen.add(pre)
        akey = (u.method, u.method_config, u.benchmark)
        _check_refusal(plan.spec, u)
        if akey not in agents:
            # settled by expand() already (resolve_methods); built again as the worker builds it:
            # from the unit's resolved settings
            agents[akey] = agent_from_config(u.method, u.method_config)
        agent = agents[akey]
        options = env_options_for(u.work(), agent)
        ekey = (kind, _canonical(options), float(u.step_multiplier))
        envs.setdefault(ekey, _EnvProbe(u, options)).methods.append((u, agent))
    return list(envs.values())


def _open_env(spec: SweepSpec, probe: _EnvProbe) -> Environment:
    """The probe's environment, opened as the worker opens it; a SpecError line when it cannot be."""
    first = probe.unit
    try:
        return registry.make_env(first.instance_id, step_multiplier=first.step_multiplier, **probe.options)
    except DataNotFoundError as exc:
        raise _data_error(spec, first, exc) from None
    except Exception as exc:
        b = first.benchmark
        head = f"environments[{_env_index(spec, b, first.env_options)}] ({b}): cannot open {first.instance_id}: "
        raise SpecError(_fit(head, _reason(exc))) from None


def _check_agents(spec: SweepSpec, env: Environment, probe: _EnvProbe) -> None:
    """Each method configuration of the probe builds its episode and renders its demonstration on ``env``."""
    method_index = {m.name: i for i, m in enumerate(spec.methods)}
    for u, agent in probe.methods:
        refused = agent.refuses_env(env)
        if refused is not None:  # the method cannot play this benchmark at all (a coding agent elsewhere)
            i = method_index.get(u.method_label)
            raise SpecError(_fit(f"methods[{i}] ({u.method_label}) cannot run on {stratum(u.instance_id)}: ", refused))
        try:
            agent.episode_config(env)
            agent.demonstration_text(env)
        except DataNotFoundError as exc:
            raise _data_error(spec, u, exc) from None
        except Exception as exc:
            i = method_index.get(u.method_label)
            head = f"methods[{i}] ({u.method_label}) cannot run on {stratum(u.instance_id)}: "
            raise SpecError(_fit(head, _reason(exc))) from None


def check_plan(plan: Plan, needs: list[str] | None = None) -> None:
    """Every unit of ``plan`` can start its episode, checked without a model call, before
    anything is written: raises :class:`~pipeline.errors.SpecError` (one line) otherwise.

    For each distinct (benchmark, task kind, method configuration, environment options, step
    multiplier) of the plan, the agent is built exactly as the episode worker builds it
    (:func:`workers.episode_worker.agent_from_config` and :func:`~workers.episode_worker.env_options_for`),
    one instance of that task kind is opened with the unit's options and step multiplier
    (:func:`workers.envs.registry.make_env`: the data folder must be found) and the agent
    renders its demonstration for it (``agent.demonstration_text(env)``). One environment is
    opened per distinct (task kind, options, step multiplier) and serves every method
    configuration that shares it, so a sweep over many instances opens a handful: ALFWorld's
    134 games under 3 methods open at most 6 task types x 2 option sets.

    Why: a unit that cannot start would otherwise fail at run time on every attempt, be stored
    as ``env_error``, count as done and show up in the report as a 0 % method.

    ``needs`` (``recap estimate``): what this machine still lacks for a run (images, a daemon:
    :meth:`~workers.envs.registry.Benchmark.run_needs`) is appended to it instead of refused, and
    the environments that need it are not opened (they cannot be, here).
    """
    check_output_caps(plan)
    lacking = check_benchmarks(plan, needs)
    for probe in _env_probes(plan):
        if (probe.unit.benchmark, _canonical(probe.unit.env_options)) in lacking:
            continue
        env = _open_env(plan.spec, probe)
        try:
            _check_agents(plan.spec, env, probe)
        finally:
            try:
                env.close()
            except Exception:
                pass
