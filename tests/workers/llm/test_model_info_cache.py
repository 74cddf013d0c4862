"""litellm's model-info lookups answer the same with the "not mapped" memory
(:mod:`workers.llm.model_info_cache`): a found model as before, an unknown one with the same
exception, without searching again until the cost map changes."""

from __future__ import annotations

from typing import Any

import pytest

from workers.llm import model_info_cache
from workers.llm.litellm_setup import get_litellm

litellm = get_litellm()


def test_installed_on_both_lookups() -> None:
    assert model_info_cache.install(litellm) is True
    assert isinstance(litellm.utils._cached_get_model_info, model_info_cache.NegativeCache)
    assert litellm.cost_calculator.cached_get_model_info_helper is litellm.utils.cached_get_model_info_helper
    with pytest.raises(Exception, match="no-such-model-for-clear"):
        litellm.get_model_info("openai/no-such-model-for-clear")
    assert litellm.utils._cached_get_model_info.misses
    litellm.get_model_info.cache_clear()  # litellm's public clear empties the remembered misses too
    assert not litellm.utils._cached_get_model_info.misses


def test_unknown_model_raises_the_same_without_searching_again() -> None:
    wrapped = litellm.utils._cached_get_model_info
    calls = []
    inner = wrapped.fn

    def counting(*args, **kwargs):
        calls.append(args)
        return inner(*args, **kwargs)

    wrapped.fn = counting
    try:
        with pytest.raises(Exception) as first:
            litellm.get_model_info("openai/no-such-model-xyz")
        with pytest.raises(Exception) as second:
            litellm.get_model_info("openai/no-such-model-xyz")
        assert type(second.value) is type(first.value) and str(second.value) == str(first.value)
        assert "no-such-model-xyz" in str(first.value)
        assert len(calls) == 1  # the second answer came from the memory
        known = litellm.get_model_info("gpt-4o")  # a mapped model: litellm's own answer
        assert known["input_cost_per_token"] > 0
    finally:
        wrapped.fn = inner


def test_a_registration_makes_a_remembered_miss_look_again() -> None:
    name = "openai/recap-test-registered-later"
    with pytest.raises(Exception, match="recap-test-registered-later"):
        litellm.get_model_info(name)
    litellm.register_model(
        {name: {"input_cost_per_token": 1e-6, "output_cost_per_token": 2e-6, "litellm_provider": "openai", "mode": "chat"}}
    )
    try:
        assert litellm.get_model_info(name)["output_cost_per_token"] == 2e-6
    finally:
        litellm.model_cost.pop(name, None)
        litellm.utils._invalidate_model_cost_lowercase_map()


def test_negative_cache_unit() -> None:
    state = {"n": 0, "gen": 0}

    def lookup(model: str) -> str:
        state["n"] += 1
        if model == "bad":
            raise ValueError("not mapped: bad")
        return model.upper()

    lookup.cache_clear = lambda: None  # type: ignore[attr-defined]
    cache = model_info_cache.NegativeCache(lookup, lambda: state["gen"])
    assert cache("ok") == "OK" and cache("ok") == "OK" and state["n"] == 2  # found answers are not ours to keep
    for _ in range(3):
        with pytest.raises(ValueError, match="not mapped: bad"):
            cache("bad")
    assert state["n"] == 3
    state["gen"] += 1  # the cost map changed
    with pytest.raises(ValueError):
        cache("bad")
    assert state["n"] == 4
    cache.cache_clear()
    assert not cache.misses


def test_bridge_check_answers_as_the_uncached_lookup(monkeypatch) -> None:
    """litellm's per-call Responses-API bridge check gets the same model info from the cached
    lookup (a copy it may write into) and the same verdict, for a mapped, an unmapped and a
    ``responses/`` model; an unmapped model is not searched again."""
    import litellm.main as main

    assert model_info_cache.install(litellm) is True
    bridge: Any = main.get_model_info_helper
    uncached = bridge.__wrapped__
    assert uncached is litellm.utils.get_model_info_helper

    known: Any = bridge(model="gpt-4o", custom_llm_provider="openai")
    assert known == uncached(model="gpt-4o", custom_llm_provider="openai") and known["input_cost_per_token"] > 0
    known["mode"] = "written by a caller"
    assert bridge(model="gpt-4o", custom_llm_provider="openai")["mode"] == "chat"  # the cache holds its own copy
    with pytest.raises(Exception) as direct:
        uncached(model="recap-bridge-unmapped", custom_llm_provider="openai")
    with pytest.raises(Exception) as cached:
        bridge(model="recap-bridge-unmapped", custom_llm_provider="openai")
    assert type(cached.value) is type(direct.value) and str(cached.value) == str(direct.value)

    cases = [("gpt-4o", "openai"), ("fake-gpt", "openai"), ("responses/gpt-4o", "openai"), ("recap-bridge-unmapped", "openai")]
    with_cache = [main.responses_api_bridge_check(model=m, custom_llm_provider=p) for m, p in cases]
    monkeypatch.setattr(main, "get_model_info_helper", uncached)
    assert with_cache == [main.responses_api_bridge_check(model=m, custom_llm_provider=p) for m, p in cases]
    monkeypatch.undo()

    searched: list[Any] = []
    helper = litellm.utils.cached_get_model_info_helper
    inner = helper.fn

    def counting(*args, **kwargs):
        searched.append(kwargs.get("model", args[0] if args else None))
        return inner(*args, **kwargs)

    helper.fn = counting
    try:
        for _ in range(3):
            main.responses_api_bridge_check(model="recap-bridge-unmapped-2", custom_llm_provider="openai")
    finally:
        helper.fn = inner
    assert searched == ["recap-bridge-unmapped-2"]  # searched once, then answered from the memory
