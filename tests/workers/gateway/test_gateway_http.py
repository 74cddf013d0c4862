"""The gateway core through litellm's real HTTP client against the fake server.

Windows are scaled down (1.5-2 s instead of 60 s) so the suite stays short.
"""

from __future__ import annotations

import asyncio
import logging

import pytest

from recap.llm import LLMError
from schemas.parts import read_table
from tests.doubles.llm_requests import FAKE_KEY_ENV, make_request
from workers.gateway.core import DeploymentGateway
from workers.llm.offline.fake_server import window_maxima
from workers.llm.providers import DeploymentConfig

MODEL = "openai/fake-gpt"  # TEST DOUBLE price: $1/M input, $0.5/M cached, $2/M output


def config(server, **kw) -> DeploymentConfig:
    args = dict(
        model=MODEL,
        api_base=server.base_url,
        window_s=2.0,
        window_pad_s=0.1,
        max_concurrency=16,
        max_attempts=3,
        backoff_initial_s=0.01,
        backoff_max_s=0.05,
        attempt_timeout_s=5.0,
        params={"max_tokens": 20},
    )
    args.update(kw)
    return DeploymentConfig(**args)


def rows(run_dir) -> list[dict]:
    return read_table(run_dir, "llm_calls")[0].to_pylist()


async def _gather(gw: DeploymentGateway, requests) -> list:
    out = await asyncio.gather(*[gw.complete(r) for r in requests], return_exceptions=True)
    await gw.aclose()
    return out


def test_rpm_window_is_never_exceeded_server_side(fake_server, run_dir):
    server = fake_server(rpm=8, window_s=2.0)
    gw = DeploymentGateway(config(server, rpm=8), run_dir=run_dir)
    out = asyncio.run(_gather(gw, [make_request(i) for i in range(20)]))
    assert all(not isinstance(r, Exception) for r in out)
    assert {c.status for c in server.log} == {200}  # not a single 429
    max_requests, _ = window_maxima(server.log, 2.0)
    assert max_requests == 8  # the limit binds and holds
    assert len(rows(run_dir)) == 20


def test_tpm_window_is_never_exceeded_server_side(fake_server, run_dir):
    server = fake_server(tpm=600, window_s=1.5)
    gw = DeploymentGateway(config(server, tpm=600, window_s=1.5), run_dir=run_dir)
    long_text = "the same kitchen, step by step. " * 13  # 416 chars: about 106 prompt tokens
    out = asyncio.run(_gather(gw, [make_request(i, f"{i:03d} {long_text}") for i in range(16)]))
    assert all(not isinstance(r, Exception) for r in out)
    assert {c.status for c in server.log} == {200}
    _, max_tokens = window_maxima(server.log, 1.5)
    assert 480 <= max_tokens <= 600


def test_fifty_concurrent_callers_never_spend_past_the_cap(fake_server, run_dir):
    server = fake_server(latency_s=0.05)
    cap = 0.002
    gw = DeploymentGateway(config(server, max_concurrency=50), run_dir=run_dir, run_cap_usd=cap)

    async def caller(c: int) -> list:
        out = []
        for j in range(4):
            try:
                out.append(await gw.complete(make_request(c * 10 + j)))
            except LLMError as exc:
                out.append(exc)
        return out

    async def go():
        results = await asyncio.gather(*[caller(c) for c in range(50)])
        stats = await gw.budget.stats()
        await gw.aclose()
        return [r for rs in results for r in rs], stats

    results, stats = asyncio.run(go())
    ok = [r for r in results if not isinstance(r, LLMError)]
    refused = [r for r in results if isinstance(r, LLMError)]
    assert {e.kind for e in refused} == {"budget"} and len(ok) + len(refused) == 200
    assert stats["spent_usd"] <= cap and stats["reserved_usd"] == 0
    assert stats["spent_usd"] >= cap / 2  # the cap, not something else, stopped the callers
    assert len(ok) == len([c for c in server.log if c.status == 200])
    recorded = rows(run_dir)
    assert len(recorded) == 200
    assert sum(r["cost_usd"] for r in recorded) == pytest.approx(stats["spent_usd"], abs=1e-12)
    assert sorted(r["error_kind"] for r in recorded if r["status"] == "error") == ["budget"] * len(refused)


CASES = [
    # directive, config overrides, expected kind, expected retries
    ("FAKE:ctx", {}, "context_length", 0),
    ("FAKE:400", {}, "bad_request", 0),
    ("FAKE:401", {}, "auth", 0),
    ("FAKE:500", {}, "server_error", 2),
    ("FAKE:503", {}, "server_error", 2),
    ("FAKE:malformed", {}, "server_error", 2),
    ("FAKE:empty", {}, "server_error", 2),
    ("FAKE:hang", {"attempt_timeout_s": 0.3, "max_attempts": 2}, "timeout", 1),
    ("FAKE:429", {"max_attempts": 2}, "rate_limit", 1),
]


@pytest.mark.parametrize("directive,overrides,kind,retries", CASES, ids=[c[2] + "-" + c[0][5:] for c in CASES])
def test_each_error_class_reaches_the_caller(fake_server, run_dir, directive, overrides, kind, retries):
    server = fake_server(hang_s=5.0)
    gw = DeploymentGateway(config(server, **overrides), run_dir=run_dir)
    out = asyncio.run(_gather(gw, [make_request(0, f"please {directive}")]))
    err = out[0]
    assert isinstance(err, LLMError) and (err.kind, err.retries) == (kind, retries)
    assert len(server.log) == retries + 1
    (row,) = rows(run_dir)
    assert (row["status"], row["error_kind"], row["retries"]) == ("error", kind, retries)
    assert row["error_message"] == err.message
    if kind == "timeout":  # a timed-out attempt may have been billed: charged at worst case
        assert err.cost_usd > 0 and row["cost_usd"] == err.cost_usd


def test_budget_and_missing_key_fail_before_any_request(fake_server, run_dir, monkeypatch):
    server = fake_server()
    monkeypatch.delenv("RECAP_TEST_NO_SUCH_KEY", raising=False)
    gw = DeploymentGateway(config(server), run_dir=run_dir, run_cap_usd=0.0)
    (err,) = asyncio.run(_gather(gw, [make_request(0)]))
    assert err.kind == "budget" and "run budget" in err.message
    other = run_dir.parent / "other"
    gw2 = DeploymentGateway(config(server, api_key_env="RECAP_TEST_NO_SUCH_KEY"), run_dir=other, run_id="o")
    (err2,) = asyncio.run(_gather(gw2, [make_request(0)]))
    assert err2.kind == "auth" and "RECAP_TEST_NO_SUCH_KEY" in err2.message
    assert server.log == []


def test_hints_and_call_context_never_reach_the_provider(fake_server, run_dir):
    server = fake_server(keep_bodies=True)
    gw = DeploymentGateway(config(server, params={"max_tokens": 20, "temperature": 0.5}), run_dir=run_dir)
    hints = {"style": "recap", "expert_plan": ["HINT-MARKER-ACTION"]}
    asyncio.run(_gather(gw, [make_request(0, "plain question", hints=hints, episode="EPISODE-MARKER")]))
    (body,) = server.bodies
    assert body["messages"] == [{"role": "user", "content": "plain question"}]
    assert (body["max_tokens"], body["temperature"]) == (20, 0.5)
    assert "HINT-MARKER" not in str(body) and "EPISODE-MARKER" not in str(body)


def test_transient_failures_are_retried_to_success(fake_server, run_dir):
    server = fake_server()
    gw = DeploymentGateway(config(server), run_dir=run_dir)
    a, b = asyncio.run(_gather(gw, [make_request(0, "x FAKE:500*2"), make_request(1, "y FAKE:malformed*1")]))
    assert (a.retries, b.retries) == (2, 1)
    assert sorted((r["call_index"], r["status"], r["retries"]) for r in rows(run_dir)) == [(0, "ok", 2), (1, "ok", 1)]


def test_provider_429s_shrink_concurrency_and_all_calls_finish(fake_server, run_dir):
    server = fake_server(rpm=4, window_s=1.0)
    gw = DeploymentGateway(config(server, max_concurrency=8, max_attempts=10), run_dir=run_dir)

    async def go():
        out = await asyncio.gather(*[gw.complete(make_request(i)) for i in range(12)])
        stats = gw.stats()
        await gw.aclose()
        return out, stats

    out, stats = asyncio.run(go())
    assert len(out) == 12 and stats["rate_limited"] >= 1 and stats["shrinks"] >= 1
    assert stats["concurrency_limit"] < 8
    assert window_maxima(server.log, 1.0)[0] <= 4


def test_repeated_call_key_and_identical_requests_are_not_paid_twice(fake_server, run_dir):
    server = fake_server(latency_s=0.1)
    gw = DeploymentGateway(config(server, cache=True), run_dir=run_dir)

    async def go():
        first, in_flight_twin = await asyncio.gather(gw.complete(make_request(0, "same")), gw.complete(make_request(0, "same")))
        again = await gw.complete(make_request(0, "same"))
        cached = await gw.complete(make_request(1, "same"))  # another call, identical request
        await gw.aclose()
        return first, in_flight_twin, again, cached

    first, twin, again, cached = asyncio.run(go())
    assert len(server.log) == 1
    assert first.served_from == "provider" and first.cost_usd > 0
    assert [(r.served_from, r.cost_usd, r.text) for r in (twin, again, cached)] == [
        ("ledger", 0.0, first.text),
        ("ledger", 0.0, first.text),
        ("cache", 0.0, first.text),
    ]
    assert sorted(r["served_from"] for r in rows(run_dir)) == ["cache", "ledger", "ledger", "provider"]


def test_cached_prompt_tokens_are_reported_and_priced(fake_server, run_dir):
    server = fake_server()
    gw = DeploymentGateway(config(server), run_dir=run_dir)
    prefix = "a long shared system prompt. " * 20  # 580 chars

    async def go():
        a = await gw.complete(make_request(0, prefix + "first question"))
        b = await gw.complete(make_request(1, prefix + "second question"))
        await gw.aclose()
        return a, b

    a, b = asyncio.run(go())
    assert a.cached_prompt_tokens == 0
    # longest common prefix "user:" + prefix = 585 chars -> 146 cached tokens
    assert b.cached_prompt_tokens == 146
    assert b.cost_usd == ((b.prompt_tokens - 146) * 1.0 + 146 * 0.5 + b.completion_tokens * 2.0) / 1e6


WRONG_KEY = "sk-wrong-SECRETVALUE-zz9yy8xx7"


def test_api_keys_never_reach_records_logs_or_errors(fake_server, run_dir, fake_key, monkeypatch, caplog):
    caplog.set_level(logging.DEBUG)
    monkeypatch.setenv("RECAP_TEST_WRONG_KEY", WRONG_KEY)
    server = fake_server(require_api_key=fake_key)
    good = DeploymentGateway(config(server, api_key_env=FAKE_KEY_ENV), run_dir=run_dir)
    ok = asyncio.run(_gather(good, [make_request(0), make_request(1, "FAKE:500*1")]))
    assert all(not isinstance(r, Exception) for r in ok)
    bad = DeploymentGateway(config(server, api_key_env="RECAP_TEST_WRONG_KEY", name="wrong"), run_dir=run_dir)
    (err,) = asyncio.run(_gather(bad, [make_request(2)]))
    assert err.kind == "auth"
    assert "[REDACTED]" in err.message and WRONG_KEY not in err.message  # the server echoed it
    files = [p for p in run_dir.rglob("*") if p.is_file()]
    assert any(p.suffix == ".parquet" for p in files) and any(p.suffix == ".jsonl" for p in files)
    for path in files:
        raw = path.read_bytes()
        assert fake_key.encode() not in raw and WRONG_KEY.encode() not in raw, path
    table_text = str(rows(run_dir))
    assert fake_key not in table_text and WRONG_KEY not in table_text
    assert "Incorrect API key provided: [REDACTED]" in table_text
    log_text = caplog.text
    assert fake_key not in log_text and WRONG_KEY not in log_text


def test_tool_calls_are_served_again_from_the_ledger_and_the_cache(fake_server, run_dir):
    """A duplicate call (same key: a retried worker) and an identical request (the cache) return the
    model's tool calls as the provider gave them, not an empty reply, and pay nothing."""
    import dataclasses

    from recap.llm import ToolDef

    server = fake_server(latency_s=0.1)
    gw = DeploymentGateway(config(server, cache=True), run_dir=run_dir)
    tools = (
        ToolDef(
            "bash", "run one command", {"type": "object", "properties": {"command": {"type": "string"}}, "required": ["command"]}
        ),
        ToolDef("view", "show a file", {"type": "object", "properties": {"path": {"type": "string"}}, "required": ["path"]}),
    )

    def request(i: int):
        return dataclasses.replace(make_request(i, "FAKE:paralleltools"), tools=tools, tool_choice="auto")

    async def go():
        first, twin = await asyncio.gather(gw.complete(request(0)), gw.complete(request(0)))
        again = await gw.complete(request(0))
        cached = await gw.complete(request(1))
        await gw.aclose()
        return first, twin, again, cached

    first, twin, again, cached = asyncio.run(go())
    assert len(server.log) == 1
    assert [(c.id, c.name, c.args) for c in first.tool_calls] == [
        ("call_fake_1_0", "bash", {"command": "fake"}),
        ("call_fake_1_1", "view", {"path": "fake"}),
    ]
    assert [(r.served_from, r.cost_usd, r.tool_calls) for r in (twin, again, cached)] == [
        ("ledger", 0.0, first.tool_calls),
        ("ledger", 0.0, first.tool_calls),
        ("cache", 0.0, first.tool_calls),
    ]
    # a request with other tools is another request: not served from the cache
    other = dataclasses.replace(request(2), tools=tools[:1])
    gw2 = DeploymentGateway(config(server, cache=True), run_dir=run_dir)

    async def go2():
        out = await gw2.complete(other)
        await gw2.aclose()
        return out

    assert asyncio.run(go2()).served_from == "provider" and len(server.log) == 2
