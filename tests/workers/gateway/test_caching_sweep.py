"""A sweep through ``recap run`` (local Ray) against the fake server with the Anthropic and the
DeepSeek caching rules: the llm_calls rows carry non-zero cached (and, for Anthropic, written)
tokens, each row's cost is its tokens at the table's prices to the pico-dollar, and
``episodes.cost_usd`` is the sum of its calls - below what the same tokens cost uncached."""

from __future__ import annotations

from pathlib import Path

import pytest

from workers.llm.pricing import default_prices

SWEEP = """run: caching
output: {out}
models:
  - model: openai/fake-claude
    api_base: {url}
    api_key_env: RECAP_FAKE_KEY
    retries: 0
    params: {{max_tokens: 64}}
  - model: openai/fake-deepseek
    api_base: {url}
    api_key_env: RECAP_FAKE_KEY
    retries: 0
    params: {{max_tokens: 64}}
methods: [{{method: react}}]
environments: [{{benchmark: blocksworld, instances: ["blocksworld/3@1"]}}]
limits: {{llm_calls: 5}}
workers: 2
"""


def test_sweep_records_cached_tokens_and_bills_them_at_the_cached_prices(ray_address, tmp_path: Path, monkeypatch):
    from pipeline.cli import main
    from pipeline.sqlview import open_tables
    from pipeline.store import RunStore
    from workers.llm.offline.fake_server import FakeServer, FakeServerConfig

    monkeypatch.setenv("RECAP_FAKE_KEY", "not-a-secret")
    # blocksworld prompts are short: the minimum cacheable prefix is lowered for the test
    server = FakeServer(
        FakeServerConfig(cache_rules={"fake-claude": "anthropic", "fake-deepseek": "deepseek"}, cache_min_tokens=0)
    )
    url = server.start_in_thread()
    out = tmp_path / "caching"
    spec = tmp_path / "sweep.yaml"
    spec.write_text(SWEEP.format(out=out, url=url))
    try:
        assert main(["run", str(spec), "--progress", "off"]) == 0
    finally:
        server.stop_thread()
    con, _ = open_tables(RunStore(out))
    calls = con.execute(
        "select episode_id, model, call_index, prompt_tokens, cached_prompt_tokens, cache_write_tokens, "
        "completion_tokens, cost_usd from llm_calls where status = 'ok' order by model, call_index"
    ).fetchall()
    episodes = dict(con.execute("select model, cost_usd from episodes").fetchall())
    ep_of = dict(con.execute("select episode_id, model from episodes").fetchall())
    assert len(calls) == 10 and set(ep_of.values()) == {"openai/fake-claude", "openai/fake-deepseek"}
    table = default_prices()
    totals: dict[str, int] = {}
    uncached: dict[str, int] = {}
    for episode_id, model, _, prompt, cached, written, completion, cost in calls:
        price = table.get(model)
        pico = price.cost_pico(prompt, cached, completion, written)
        assert cost == pico / 1e12  # each row: its tokens at the table's prices, exactly
        totals[model] = totals.get(model, 0) + pico
        uncached[model] = uncached.get(model, 0) + price.cost_pico(prompt, 0, completion)
        assert ep_of[episode_id] == model
    by_model = {m: [c for c in calls if c[1] == m] for m in ("openai/fake-claude", "openai/fake-deepseek")}
    # claude: call 0 marks nothing, call 1 writes what it shares with call 0, later calls read it
    claude = by_model["openai/fake-claude"]
    assert [c[4] > 0 for c in claude] == [False, False, True, True, True]
    assert [c[5] > 0 for c in claude] == [False, True, True, True, True]
    # deepseek: from the second call on, the previous call's prompt + reply unit is hit
    assert [c[4] > 0 for c in by_model["openai/fake-deepseek"]] == [False, True, True, True, True]
    for model, pico in totals.items():
        assert episodes[model] == pytest.approx(pico / 1e12, abs=1e-12)  # the episode is its calls' sum
        assert round(episodes[model], 2) == round(pico / 1e12, 2)
        assert pico < uncached[model]  # the discount reached the episode's cost
    cached_sum = dict(con.execute("select model, cached_prompt_tokens from episodes").fetchall())
    assert all(v > 0 for v in cached_sum.values())
