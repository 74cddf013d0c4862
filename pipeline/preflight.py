"""Checks that must pass before a sweep spends anything: API keys present, prices known for
every model a dollar cap applies to.

Why before everything: a missing key discovered at the first call of the first episode would
turn a night's run into hundreds of ``auth`` failures; a cap on a model whose calls cannot be
priced cannot be enforced at all. Both are reported as one line, before any write.
"""

from __future__ import annotations

import os

from pipeline.errors import PreflightError
from pipeline.spec import ModelSpec, SweepSpec


def _litellm_missing_keys(m: ModelSpec) -> list[str]:
    from workers.llm.litellm_setup import get_litellm

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
    if m.test_double:
        return []
    if m.api_key_env:
        return [m.api_key_env]
    from unittest import mock

    with mock.patch.dict(os.environ, {"LITELLM_LOCAL_MODEL_COST_MAP": "True"}, clear=True):
        return _litellm_missing_keys(m)


def check_keys(spec: SweepSpec) -> None:
    for i, m in enumerate(spec.models):
        if m.test_double:
            continue
        if m.api_key_env:
            if not os.environ.get(m.api_key_env):
                raise PreflightError(f"models[{i}] ({m.name}): API key variable {m.api_key_env} is not set")
            continue
        missing = _litellm_missing_keys(m)
        if missing:
            raise PreflightError(f"models[{i}] ({m.name}): API key missing: set {' or '.join(missing)} (or name another variable with api_key_env)")


def check_prices(spec: SweepSpec) -> None:
    """Every model under a cap (the run cap covers all models) must have a price."""
    from workers.llm.pricing import PriceError, require_prices

    for i, m in enumerate(spec.models):
        if spec.run_cap_usd is None and m.cap_usd is None:
            continue
        overrides = {m.model: m.prices.model_dump()} if m.prices is not None else None
        try:
            require_prices([m.model], overrides)
        except PriceError as exc:
            which = "run cap" if m.cap_usd is None else "model cap"
            raise PreflightError(f"models[{i}] ({m.name}) has a {which} but no price: {exc}") from None


def preflight(spec: SweepSpec) -> None:
    check_prices(spec)
    check_keys(spec)
