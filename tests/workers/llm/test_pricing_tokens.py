"""Prices from the repo table (exact integer costs) and offline token counts."""

from __future__ import annotations

import time

import pytest

from workers.llm.litellm_setup import get_litellm
from workers.llm.pricing import Price, PriceError, PriceTable, default_prices, require_prices
from workers.llm.tokens import count_prompt_tokens, prompt_token_bound


def test_gpt4o_cost_uses_cached_input_price():
    price = default_prices().get("openai/gpt-4o")
    assert (price.input, price.cached_input, price.output) == (2.50, 1.25, 10.00)
    # 800 uncached * 2.5e-6 + 200 cached * 1.25e-6 + 100 * 1e-5 = 0.00325 USD
    assert price.cost_pico(1000, 200, 100) == 3_250_000_000
    assert price.cost_usd(1000, 200, 100) == 0.00325


def test_lookup_strips_provider_prefix_and_marks_test_doubles():
    table = default_prices()
    assert table.get("gpt-4o-mini") == table.get("openai/gpt-4o-mini")
    assert table.get("openai/fake-gpt").test_double is True
    assert table.get("offline/expert").test_double is True
    assert table.get("together_ai/Qwen/Qwen2.5-72B-Instruct-Turbo").cached_input is None
    assert table.get("deepseek/deepseek-chat").rates() == (280_000, 28_000, 420_000)
    assert table.get("no-such/model") is None


def test_require_prices_names_every_missing_model_and_accepts_overrides():
    with pytest.raises(PriceError) as err:
        require_prices(["openai/gpt-4o", "acme/model-a", "acme/model-b"])
    assert "no price for model(s) acme/model-a, acme/model-b" in str(err.value)
    found = require_prices(["acme/model-a"], {"acme/model-a": {"input": 0.5, "output": 1.5}})
    assert found["acme/model-a"].cost_pico(10, 0, 10) == 10 * 500_000 + 10 * 1_500_000


def test_malformed_prices_are_refused():
    with pytest.raises(PriceError, match="more than 6 decimals"):
        Price(input=0.0000001, output=1.0)
    with pytest.raises(PriceError, match="needs 'output'"):
        PriceTable({}).with_overrides({"m": {"input": 1.0}})
    with pytest.raises(PriceError, match="unknown price field"):
        PriceTable({}).with_overrides({"m": {"input": 1.0, "output": 1.0, "cache": 1.0}})


def test_openai_models_are_counted_with_the_bundled_tokenizer():
    messages = [{"role": "user", "content": "Put the onion on the cutting board, then cut it."}]
    counted = count_prompt_tokens("openai/gpt-4o", messages)
    assert counted.source == "tokenizer"
    assert counted.tokens == get_litellm().token_counter(model="gpt-4o", messages=messages)


def test_other_models_get_the_documented_estimate_without_network():
    messages = [{"role": "user", "content": "x" * 41}, {"role": "assistant", "content": "ok"}]
    t0 = time.monotonic()
    counted = count_prompt_tokens("together_ai/meta-llama/Llama-3.3-70B-Instruct-Turbo", messages)
    assert time.monotonic() - t0 < 1.0  # no tokenizer download attempted
    # 3 (reply priming) + (3 + ceil(41/4)) + (3 + ceil(2/4))
    assert (counted.tokens, counted.source) == (3 + 14 + 4, "estimate")
    # upper bound for the budget: one token per UTF-8 byte plus template allowance
    assert prompt_token_bound("together_ai/x", messages, counted) == 32 + (16 + 41) + (16 + 2)


def test_list_price_bills_with_cache_reads_and_writes_equal_hand_computed_totals():
    table = default_prices()
    # GPT-4o: 2M prompt tokens of which 1.5M cached, 100k out:
    # 0.5 x $2.50 + 1.5 x $1.25 + 0.1 x $10 = $4.125 (writes are free: no write price)
    gpt = table.get("openai/gpt-4o")
    assert gpt.cost_usd(2_000_000, 1_500_000, 100_000) == 4.125
    # Claude Sonnet 4.5: 2M prompt = 1.5M read + 0.4M written + 0.1M plain, 100k out:
    # 0.1 x $3 + 1.5 x $0.30 + 0.4 x $3.75 + 0.1 x $15 = $3.75
    claude = table.get("anthropic/claude-sonnet-4-5")
    assert (claude.input, claude.cached_input, claude.cache_write, claude.output) == (3.0, 0.3, 3.75, 15.0)
    assert claude.explicit_cache is True and gpt.explicit_cache is False
    assert claude.cost_usd(2_000_000, 1_500_000, 100_000, 400_000) == 3.75
    # DeepSeek-chat: 2M prompt, 1.5M cache hits, 100k out: 0.5 x $0.28 + 1.5 x $0.028 + 0.1 x $0.42 = $0.224
    assert table.get("deepseek/deepseek-chat").cost_usd(2_000_000, 1_500_000, 100_000) == 0.224
    # one call to the cent: 23,456 prompt tokens (20,000 read, 3,000 written), 512 out on Claude
    assert (
        round(claude.cost_usd(23_456, 20_000, 512, 3_000), 2)
        == round((456 * 3 + 20_000 * 0.3 + 3_000 * 3.75 + 512 * 15) / 1e6, 2)
        == 0.03
    )
    assert (
        claude.cost_pico(23_456, 20_000, 512, 3_000) == 456 * 3_000_000 + 20_000 * 300_000 + 3_000 * 3_750_000 + 512 * 15_000_000
    )


def test_cache_counts_beyond_the_prompt_are_clamped_in_the_price():
    price = Price(input=1.0, output=2.0, cached_input=0.1, cache_write=1.25)
    # reads take precedence, writes fill at most the rest of the prompt
    assert price.cost_pico(100, 80, 0, 50) == 80 * 100_000 + 20 * 1_250_000
    assert price.cost_pico(100, 0, 0, 0) == 100 * 1_000_000
    assert price.write_rate() == 1_250_000 and price.max_input_rate() == 1_250_000
    assert Price(input=1.0, output=2.0).write_rate() == 1_000_000


def test_price_flags_must_be_booleans():
    with pytest.raises(PriceError, match="explicit_cache must be true or false, got 'no'"):
        PriceTable({}).with_overrides({"m": {"input": 1.0, "output": 1.0, "explicit_cache": "no"}})


def _uncached_count(model: str, messages: list[dict], tools: list[dict] | None = None) -> int:
    """The count as it was made before the per-text memory: every text encoded on every call."""
    from workers.llm.tokens import REPLY_PRIMING_TOKENS, TOKENS_PER_MESSAGE, TOKENS_PER_TOOL, _content, _encoding_for, tools_text

    enc = _encoding_for(model)
    n = REPLY_PRIMING_TOKENS
    for m in messages:
        n += TOKENS_PER_MESSAGE + len(enc.encode(_content(m), disallowed_special=()))
        n += len(enc.encode(str(m.get("role", "")), disallowed_special=()))
    if tools:
        n += len(enc.encode(tools_text(tools), disallowed_special=())) + TOKENS_PER_TOOL * len(tools)
    return n


def test_remembered_counts_equal_fresh_counts_over_a_growing_conversation() -> None:
    """A ReAct-like episode re-sends its whole conversation each call: the memoised count of
    every call equals the count with every text encoded afresh, and the re-sent texts are hits."""
    from workers.llm.tokens import _lengths_for

    model = "openai/gpt-4o"
    lengths = _lengths_for(model)
    assert lengths is not None
    system = "You act in a kitchen; answer with one action per turn. " * 20  # long: memoised
    messages: list[dict] = [{"role": "system", "content": system}]
    tools = [{"type": "function", "function": {"name": "act", "parameters": {"type": "object", "properties": {}}}}]
    hits0 = lengths.hits
    for i in range(6):
        messages.append({"role": "user", "content": f"Observation {i}: " + "the pot is on the stove, the onion is cut. " * 8})
        counted = count_prompt_tokens(model, messages, tools if i % 2 else None)
        assert counted.source == "tokenizer"
        assert counted.tokens == _uncached_count(model, messages, tools if i % 2 else None)
        messages.append(
            {
                "role": "assistant",
                "content": None,
                "tool_calls": [{"id": f"c{i}", "type": "function", "function": {"name": "act", "arguments": '{"a": "stir"}'}}],
            }
        )
        messages.append({"role": "tool", "tool_call_id": f"c{i}", "content": "done ✓ " * 60})
    assert lengths.hits - hits0 >= 15  # the system prompt and the earlier observations, re-sent


def test_remembered_counts_are_bounded_and_exact_after_eviction() -> None:
    from workers.llm.tokens import EncodedLengths, _encoding_for

    enc = _encoding_for("openai/gpt-4o")
    lengths = EncodedLengths(enc, max_entries=3, min_chars=1)
    texts = [f"text number {i} " * (i + 1) for i in range(8)]
    for t in texts + texts[::-1]:
        assert lengths(t) == len(enc.encode(t, disallowed_special=()))
    assert len(lengths._counts) == 3
    short = EncodedLengths(enc)  # below min_chars: encoded directly, nothing remembered
    assert short("hi") == len(enc.encode("hi")) and not short._counts
