"""A provider that lies, stalls or leaks, through litellm's real HTTP client against the fake
server: caps hold whatever usage it reports (n choices, negative / zero / huge / missing usage,
a negative cost figure), calls are never charged below the floor, a Retry-After beyond the cap
fails fast, and credentials in the base URL or echoed in a reply never reach a record."""

from __future__ import annotations

import asyncio
import base64
import dataclasses
import json
import logging
import math
import time

import pytest

from recap.llm import LLMError
from schemas.parts import read_table
from tests.doubles.llm_requests import FAKE_KEY_ENV, make_request
from workers.gateway.call_log import CallLog
from workers.gateway.core import DeploymentGateway
from workers.gateway.ledger import JOURNAL_NAME
from workers.gateway.limits import AdmissionController
from workers.llm.accounting import COMPLETION_SLACK_TOKENS, USAGE_REJECTED_EVENT, Sizing, settle, size_request, worst_case_pico
from workers.llm.calling import Attempt
from workers.llm.direct import LiteLLMClient
from workers.llm.pricing import Price, default_prices, pico_to_usd
from workers.llm.providers import DeploymentConfig, provider_messages, redact_url, url_secrets
from workers.llm.tokens import TokenCount

MODEL = "openai/fake-gpt"  # TEST DOUBLE price: $1/M input, $0.5/M cached, $2/M output
PRICE = default_prices().get(MODEL)


def config(server, **kw) -> DeploymentConfig:
    args = dict(
        model=MODEL,
        api_base=server.base_url,
        max_concurrency=4,
        max_attempts=2,
        backoff_initial_s=0.01,
        backoff_max_s=0.05,
        attempt_timeout_s=5.0,
        params={"max_tokens": 20},
    )
    args.update(kw)
    return DeploymentConfig(**args)


def table(run_dir, name: str) -> list[dict]:
    tables = read_table(run_dir, name)
    return tables[0].to_pylist() if tables else []


def events(run_dir, kind: str) -> list[dict]:
    return [dict(e, detail=json.loads(e["detail"])) for e in table(run_dir, "events") if e["kind"] == kind]


def test_a_reply_the_client_cannot_read_is_charged_its_reservation_and_the_cap_holds(fake_server, run_dir):
    """Fractional token counts make litellm refuse an HTTP 200 reply (it raises a 500-class
    error): the provider answered, so each such attempt is charged at its reservation and a
    run cap still binds - before, each was charged $0 and the cap never did."""
    server = fake_server()
    cap = 0.001
    gw = DeploymentGateway(config(server), run_dir=run_dir, run_cap_usd=cap)
    out, stats = spend_until_refused(gw, lambda i: f"question {i:03d} FAKE:fracusage")
    assert out[-1].kind == "budget" and len(out) < 200
    assert all(isinstance(r, LLMError) and r.kind in ("server_error", "budget") for r in out)
    assert stats["spent_usd"] <= cap and stats["overruns"] == 0
    assert stats["spent_pico"] >= true_bill_pico(server) > 0
    charged = [r.cost_usd for r in out if r.kind == "server_error"]
    assert charged and all(c > 0 for c in charged)


def true_bill_pico(server) -> int:
    """What the fake provider really generated (its own counts, not the usage it reported)."""
    return sum(PRICE.cost_pico(c.prompt_tokens, c.cached_tokens, c.completion_tokens) for c in server.log if c.status == 200)


def spend_until_refused(gw: DeploymentGateway, content, limit: int = 200) -> tuple[list, dict]:
    """Sequential calls until the budget refuses one; (responses, ledger stats)."""

    async def go():
        out = []
        for i in range(limit):
            try:
                out.append(await gw.complete(make_request(i, content(i))))
            except LLMError as exc:
                out.append(exc)
                if exc.kind == "budget":
                    break
        stats = await gw.budget.stats()
        await gw.aclose()
        return out, stats

    return asyncio.run(go())


# ---- 1a. parameters that multiply the output ----


@pytest.mark.parametrize("name", ["n", "best_of"])
def test_choice_multipliers_other_than_one_are_refused_at_config_time(name):
    with pytest.raises(ValueError, match=f"{name} must be 1: the gateway sends one choice per call"):
        DeploymentConfig(model=MODEL, params={name: 8})
    with pytest.raises(ValueError, match=f"{name} must be 1"):
        DeploymentConfig(model=MODEL, params={name: True})
    if name == "n":
        assert DeploymentConfig(model=MODEL, params={"n": 1}).params == {"n": 1}
    else:  # not a chat-completions param: refused whatever its value
        with pytest.raises(ValueError, match="unknown generation param"):
            DeploymentConfig(model=MODEL, params={"best_of": 1})


def test_n_choices_that_slip_past_the_config_are_reserved_and_the_cap_holds(fake_server, run_dir):
    server = fake_server(keep_bodies=True)
    cap = 0.002
    # model_copy does not validate: the gateway itself must still size n choices
    cfg = config(server).model_copy(update={"params": {"max_tokens": 20, "n": 8}})
    gw = DeploymentGateway(cfg, run_dir=run_dir, run_cap_usd=cap)
    out, stats = spend_until_refused(gw, lambda i: f"question {i:03d}")
    ok = [r for r in out if not isinstance(r, LLMError)]
    assert ok and isinstance(out[-1], LLMError) and out[-1].kind == "budget"
    assert {b["n"] for b in server.bodies} == {8}  # the fake server answered 8 choices per call
    assert all(c.completion_tokens == 8 * 12 for c in server.log)
    assert stats["spent_usd"] <= cap and stats["overruns"] == 0
    assert stats["spent_pico"] >= true_bill_pico(server)  # never billed below what was generated
    sizing = size_request(MODEL, provider_messages(make_request(0, "question 000").messages), cfg.params | {"max_tokens": 20})
    assert sizing.choices == 8 and sizing.output_bound == 8 * 20 + COMPLETION_SLACK_TOKENS


# ---- 1b. usage the provider reports ----

LIES = ["negusage", "zerousage", "hugeusage", "nousage", "negcached"]


@pytest.mark.parametrize("mode", LIES)
def test_impossible_usage_is_charged_at_worst_case_and_the_cap_holds(fake_server, run_dir, mode):
    server = fake_server()
    cap = 0.001
    cfg = config(server)
    gw = DeploymentGateway(cfg, run_dir=run_dir, run_cap_usd=cap)
    out, stats = spend_until_refused(gw, lambda i: f"question {i:03d} FAKE:{mode}")
    ok = [r for r in out if not isinstance(r, LLMError)]
    assert len(ok) >= 2 and out[-1].kind == "budget"
    assert stats["spent_usd"] <= cap and stats["reserved_usd"] == 0 and stats["overruns"] == 0
    assert stats["spent_pico"] >= true_bill_pico(server)
    worst = worst_case_pico(
        PRICE,
        size_request(
            MODEL,
            provider_messages(make_request(0, f"question 000 FAKE:{mode}").messages),
            cfg.generation_params(None, None, False),
        ),
    )
    for r in ok:  # each answer: charged at its reservation, recorded with our own counts
        assert r.cost_usd == pico_to_usd(worst)
        assert r.token_count_source == "estimate" and r.prompt_tokens > 0 and r.completion_tokens > 0
        assert r.provider_cost_usd is None or r.provider_cost_usd >= 0
    rejected = events(run_dir, USAGE_REJECTED_EVENT)
    assert len(rejected) == len(ok) and {e["severity"] for e in rejected} == {"error"}
    assert all(e["detail"]["problems"] and e["detail"]["charged_usd"] == pico_to_usd(worst) for e in rejected)
    rows = [r for r in table(run_dir, "llm_calls") if r["status"] == "ok"]
    assert all(r["prompt_tokens"] >= 0 and r["completion_tokens"] >= 0 for r in rows)
    assert sum(r["cost_usd"] for r in rows) == pytest.approx(stats["spent_usd"], abs=1e-12)


def test_concurrent_callers_against_a_provider_that_lies_at_random_never_pass_the_cap(fake_server, run_dir):
    server = fake_server(latency_s=0.02, fault_rates={"negusage": 0.3, "zerousage": 0.2, "hugeusage": 0.2}, seed=7)
    cap = 0.003
    gw = DeploymentGateway(config(server, max_concurrency=20), run_dir=run_dir, run_cap_usd=cap)

    async def caller(c: int) -> list:
        out = []
        for j in range(6):
            try:
                out.append(await gw.complete(make_request(c * 10 + j, f"caller {c} question {j}")))
            except LLMError as exc:
                out.append(exc)
        return out

    async def go():
        results = await asyncio.gather(*[caller(c) for c in range(20)])
        stats = await gw.budget.stats()
        await gw.aclose()
        return [r for rs in results for r in rs], stats

    results, stats = asyncio.run(go())
    assert {r.kind for r in results if isinstance(r, LLMError)} == {"budget"}
    assert stats["spent_usd"] <= cap and stats["reserved_usd"] == 0 and stats["overruns"] == 0
    assert stats["spent_pico"] >= true_bill_pico(server)
    lies = sum(1 for c in server.log if c.status == 200 and c.mode != "ok")
    assert lies >= 3 and len(events(run_dir, USAGE_REJECTED_EVENT)) == lies


def test_a_negative_or_nan_cost_figure_never_lowers_spend(fake_server, run_dir, monkeypatch):
    import workers.gateway.core as core

    real = core.attempt_async
    figures = iter([-5.0, float("nan"), float("inf")])

    async def lying(kwargs):
        return dataclasses.replace(await real(kwargs), litellm_cost_usd=next(figures))

    monkeypatch.setattr(core, "attempt_async", lying)
    server = fake_server()
    cap = 0.01
    gw = DeploymentGateway(config(server), run_dir=run_dir, run_cap_usd=cap)

    async def go():
        out = [await gw.complete(make_request(i)) for i in range(3)]
        stats = await gw.budget.stats()
        await gw.aclose()
        return out, stats

    out, stats = asyncio.run(go())
    assert all(r.cost_usd > 0 and r.provider_cost_usd is None for r in out)
    assert stats["spent_pico"] >= true_bill_pico(server) and stats["spent_usd"] <= cap
    assert len(events(run_dir, USAGE_REJECTED_EVENT)) == 3
    # unpriced: litellm's figure is the cost only when it is a valid amount
    sizing = Sizing(TokenCount(10, "estimate"), 80, 20, 1)
    att = Attempt("hello", "stop", 10, 0, 2, -3.0)
    assert settle("x/unpriced", None, att, sizing).cost_pico == 0
    assert settle("x/unpriced", None, dataclasses.replace(att, litellm_cost_usd=1e-6), sizing).cost_pico == 10**6


def test_under_reported_but_plausible_usage_is_charged_the_floor(fake_server, run_dir):
    text = "tell me about the kitchen, step by step. " * 10  # 410 chars: 103 + 6 = 109 prompt tokens
    server = fake_server(usage_override={"prompt_tokens": 40, "completion_tokens": 3})
    gw = DeploymentGateway(config(server), run_dir=run_dir, run_cap_usd=1.0)

    async def go():
        r = await gw.complete(make_request(0, text))
        await gw.aclose()
        return r

    resp = asyncio.run(go())
    (arrival,) = server.log
    assert (resp.prompt_tokens, resp.completion_tokens, resp.token_count_source) == (40, 3, "provider")
    # the floor: our count of the prompt at the input price + our count of the reply at the output price
    assert arrival.prompt_tokens == 109 and arrival.completion_tokens == 12
    assert resp.cost_usd == (109 * 1.0 + 12 * 2.0) / 1e6 > (40 * 1.0 + 3 * 2.0) / 1e6
    assert events(run_dir, USAGE_REJECTED_EVENT) == []


def test_settlement_rules_without_a_server():
    price = Price(input=1.0, cached_input=0.5, output=2.0)
    sizing = Sizing(TokenCount(100, "estimate"), 300, 20, 1)
    worst = price.cost_pico(300, 0, 20 + COMPLETION_SLACK_TOKENS)

    def attempt(p, c, cached=0, text="x" * 40, cost=None):  # the reply: 10 tokens by our count
        return Attempt(text, "stop", p, cached, c, cost)

    honest = settle(MODEL, price, attempt(100, 10, cached=60), sizing)
    assert not honest.rejected and honest.cost_pico == price.cost_pico(100, 60, 10) == honest.floor_pico
    assert settle(MODEL, price, attempt(120, 12), sizing).cost_pico == price.cost_pico(120, 0, 12)
    impossible = {
        "negative prompt": attempt(-5, 10),
        "zero prompt": attempt(0, 10),
        "zero completion": attempt(100, 0),
        "prompt far below our count": attempt(24, 10),
        "prompt above the bound": attempt(301, 10),
        "completion above max_tokens": attempt(100, 20 + COMPLETION_SLACK_TOKENS + 1),
        "missing": attempt(None, None),
        "cached above prompt": attempt(100, 10, cached=101),
        "negative cached": attempt(100, 10, cached=-1),
        "negative cost": attempt(100, 10, cost=-0.1),
        "NaN cost": attempt(100, 10, cost=math.nan),
        "malformed": dataclasses.replace(attempt(None, 10), malformed=("prompt_tokens 10.5 is not a whole number",)),
    }
    for name, att in impossible.items():
        s = settle(MODEL, price, att, sizing)
        assert s.rejected and s.cost_pico == worst, name
        assert s.usage.token_count_source == "estimate" and s.usage.prompt_tokens == 100, name
    # within tolerance: accepted, and never above the reservation
    edge = settle(MODEL, price, attempt(300, 20 + COMPLETION_SLACK_TOKENS), sizing)
    assert not edge.rejected and edge.cost_pico == worst


# ---- 2. Retry-After ----


def test_a_retry_after_beyond_the_cap_fails_fast_as_rate_limit(fake_server, run_dir):
    server = fake_server()  # FAKE:retrylong answers 429 with Retry-After: 3600
    assert DeploymentConfig(model=MODEL).max_retry_after_s == 120
    gw = DeploymentGateway(config(server, max_attempts=5), run_dir=run_dir)

    async def go():
        t0 = time.monotonic()
        try:
            await gw.complete(make_request(0, "FAKE:retrylong"))
        except LLMError as exc:
            err = exc
        elapsed = time.monotonic() - t0
        after = await gw.complete(make_request(1, "an ordinary question"))  # the deployment is not paused
        stats = gw.stats()
        await gw.aclose()
        return err, elapsed, after, stats, time.monotonic() - t0

    err, elapsed, after, stats, total = asyncio.run(go())
    assert err.kind == "rate_limit" and err.retries == 0 and "Retry-After" in err.message
    assert "3600s" in err.message and "max_retry_after_s=120" in err.message
    assert elapsed < 5 and total < 10 and after.served_from == "provider"
    assert stats["paused_until"] is None and stats["rate_limited"] == 1
    assert [c.status for c in server.log] == [429, 200]
    (failed,) = events(run_dir, "call_failed")
    assert failed["detail"]["kind"] == "rate_limit" and failed["detail"]["retry_after_s"] == 3600


def test_a_retry_after_below_the_cap_is_waited_and_shown_as_paused_until(fake_server, run_dir):
    server = fake_server(retry_after_s=1.5)
    gw = DeploymentGateway(config(server, max_retry_after_s=2.0, max_attempts=3), run_dir=run_dir)

    async def go():
        t0 = time.monotonic()
        task = asyncio.ensure_future(gw.complete(make_request(0, "x FAKE:429*1")))
        seen = None
        while not task.done():
            s = gw.stats()
            if s["paused_until"] is not None and seen is None:
                seen = (s["paused_until"], time.time(), s["retry_after_pause_s"])
            await asyncio.sleep(0.02)
        resp = await task
        elapsed = time.monotonic() - t0
        stats = gw.stats()
        await gw.aclose()
        return resp, elapsed, seen, stats

    resp, elapsed, seen, stats = asyncio.run(go())
    assert resp.retries == 1 and elapsed >= 1.4
    paused_until, wall, left = seen
    assert 0 < paused_until - wall <= 1.5 + 0.05 and left > 0  # epoch seconds, in the near future
    assert stats["paused_until"] is None


def test_retry_after_as_an_http_date_is_read_and_capped_too():
    import email.utils

    from workers.llm.errors import retry_after_seconds

    class Limited(Exception):
        def __init__(self, value):
            self.litellm_response_headers = {"Retry-After": value}

    in_an_hour = email.utils.formatdate(time.time() + 3600, usegmt=True)
    assert retry_after_seconds(Limited(in_an_hour)) == pytest.approx(3600, abs=5)
    assert retry_after_seconds(Limited("Mon, 01 Jan 2001 00:00:00 GMT")) == 0.0
    assert retry_after_seconds(Limited("soon")) is None and retry_after_seconds(Limited("inf")) == math.inf


def test_the_direct_client_also_refuses_a_long_retry_after(fake_server):
    server = fake_server()
    client = LiteLLMClient(config(server, max_attempts=4))
    t0 = time.monotonic()
    with pytest.raises(LLMError) as err:
        client.complete(make_request(0, "FAKE:retrylong"))
    assert err.value.kind == "rate_limit" and time.monotonic() - t0 < 5 and len(server.log) == 1


def test_progress_figures_read_the_request_and_the_token_windows():
    now = [100.0]

    async def run():
        ac = AdmissionController(rpm=100, tpm=10_000, window_s=60.0, pad_s=0.0, max_concurrency=8, clock=lambda: now[0])
        a, b, c = await ac.acquire(100), await ac.acquire(200), await ac.acquire(300)
        s = ac.stats()
        assert (s["window_requests"], s["window_tokens"]) == (3, 600)
        ac.release(a, "ok", actual_tokens=50)  # the reported usage replaces the estimate
        assert (ac.stats()["window_requests"], ac.stats()["window_tokens"]) == (3, 550)
        now[0] = 120.0
        ac.release(b, "ok", actual_tokens=200)
        ac.release(c, "rate_limit", retry_after_s=30.0)
        s = ac.stats()
        assert s["paused_until"] == pytest.approx(time.time() + 30.0, abs=1.0)
        assert s["retry_after_pause_s"] == 30.0
        now[0] = 161.0  # a's window (ended at 100 + 60) is over; b and c count until 180
        assert (ac.stats()["window_requests"], ac.stats()["window_tokens"]) == (2, 500)
        assert ac.stats()["paused_until"] is None
        d = await ac.acquire(10)
        ac.release(d, "rate_limit", retry_after_s=3600.0, pause=False)
        assert ac.stats()["paused_until"] is None
        now[0] = 500.0
        assert (ac.stats()["window_requests"], ac.stats()["window_tokens"]) == (0, 0)

    asyncio.run(run())


# ---- 3. credentials ----


def test_base_url_credentials_are_stripped_from_every_name():
    url = "https://alice:pa%24ss-w0rd@api.example.com:8443/v1?api_key=QK-123456&region=eu&token=T0KEN-xyz"
    assert redact_url(url) == "https://api.example.com:8443/v1?region=eu"
    assert redact_url("http://127.0.0.1:8000/v1") == "http://127.0.0.1:8000/v1"
    assert redact_url("/runs/some/folder") == "/runs/some/folder"
    cfg = DeploymentConfig(model="openai/x", api_base=url, api_key_env="SOME_KEY")
    assert cfg.deployment_name == "openai/x@https://api.example.com:8443/v1?region=eu#SOME_KEY"
    assert cfg.api_base == url  # the provider still gets the real URL
    secrets = url_secrets(url)
    for s in (
        "pa%24ss-w0rd",
        "pa$ss-w0rd",
        "alice:pa%24ss-w0rd",
        "QK-123456",
        "T0KEN-xyz",
        base64.b64encode(b"alice:pa$ss-w0rd").decode(),
    ):
        assert s in secrets
    for text in (repr(cfg), str(cfg)):
        assert "pa%24ss" not in text and "QK-123456" not in text and "T0KEN" not in text


def test_base_url_credentials_never_reach_a_file_a_row_or_a_log(fake_server, run_dir, caplog):
    caplog.set_level(logging.DEBUG)
    server = fake_server()
    password = "Zq9-S3cretPassw0rd"
    api_base = server.base_url.replace("http://", f"http://alice:{password}@") + "?api_key=QK-0987654321"
    cfg = config(server, api_base=api_base)
    name = f"{MODEL}@{server.base_url}"
    gw = DeploymentGateway(cfg, run_dir=run_dir, run_cap_usd=1.0)

    async def go():
        out = []
        for i, text in enumerate(["hello", "x FAKE:500*1", "FAKE:400", "FAKE:echokey"]):
            try:
                out.append(await gw.complete(make_request(i, text)))
            except LLMError as exc:  # litellm's async transport refuses URL credentials beside a key
                out.append(exc)
        await gw.aclose()
        return out

    via_gateway = asyncio.run(go())
    # the sync path (httpx) sends the URL's userinfo as HTTP Basic auth; the reply echoes it
    log = CallLog(run_dir, "test-run", "direct-writer")
    direct = LiteLLMClient(
        config(server, api_base=server.base_url.replace("http://", f"http://alice:{password}@")), record_sink=log.add
    )
    echoed = direct.complete(make_request(9, "FAKE:echokey"))
    log.flush()
    assert echoed.text == "your key is Basic [REDACTED] and Basic [REDACTED]"
    forms = [password, f"alice:{password}", base64.b64encode(f"alice:{password}".encode()).decode(), "QK-0987654321"]
    files = list(run_dir.rglob("*"))
    assert any(p.suffix == ".parquet" for p in files) and (run_dir / JOURNAL_NAME).exists()
    for path in files:
        assert not any(f in str(path) for f in forms), path
        if path.is_file():
            raw = path.read_bytes()
            assert not any(f.encode() in raw for f in forms), path
    calls = table(run_dir, "llm_calls")
    assert len(calls) == 5 and {r["deployment"] for r in calls} == {name, f"{MODEL}@{server.base_url}"}
    assert not any(f in str(calls + table(run_dir, "events")) for f in forms)
    assert not any(f in str(r) for r in [*via_gateway, echoed] for f in forms)
    assert not any(f in caplog.text for f in forms)


def test_an_echoed_api_key_is_redacted_for_the_agent_and_in_every_record(fake_server, run_dir, fake_key):
    server = fake_server()
    gw = DeploymentGateway(config(server, api_key_env=FAKE_KEY_ENV, cache=True), run_dir=run_dir)

    async def go():
        first = await gw.complete(make_request(0, "FAKE:echokey"))
        again = await gw.complete(make_request(0, "FAKE:echokey"))  # the same call: from the ledger
        cached = await gw.complete(make_request(1, "FAKE:echokey"))  # an identical request: cache
        await gw.aclose()
        return first, again, cached

    first, again, cached = asyncio.run(go())
    assert first.text == "your key is [REDACTED] and [REDACTED]"
    assert (again.served_from, again.text) == ("ledger", first.text)
    assert (cached.served_from, cached.text) == ("cache", first.text)
    assert len(server.log) == 1
    for path in run_dir.rglob("*"):
        if path.is_file():
            assert fake_key.encode() not in path.read_bytes(), path
    direct = LiteLLMClient(config(server, api_key_env=FAKE_KEY_ENV))
    assert direct.complete(make_request(2, "FAKE:echokey")).text == "your key is [REDACTED] and [REDACTED]"
