"""An HTTP 200 that is not a usable reply, through litellm's real HTTP client against the fake
server (issue 24, class 1): a body that is not JSON, cut short or an HTML page, and a chat
completion without a usable choice are each a ``server_error`` that may have been billed -
charged at its reservation (never $0), retried within the call's attempts, then failed; a cap
still holds against a provider that answers nothing else. A provider whose usage is rejected as
impossible is refused after ``max_usage_rejections`` replies."""

from __future__ import annotations

import asyncio
import json

import pytest

from recap.llm import LLMError
from tests.doubles.llm_requests import make_request
from workers.gateway.core import DeploymentGateway
from workers.gateway.entries import journal_spend
from workers.gateway.ledger import JOURNAL_NAME
from workers.llm.accounting import size_request, worst_case_pico
from workers.llm.offline.fake_server import UNREADABLE_MODES
from workers.llm.pricing import pico_to_usd
from workers.llm.providers import provider_messages

from .test_hostile_provider import MODEL, PRICE, config, events, spend_until_refused, table, true_bill_pico


def worst_of(content: str, cfg) -> int:
    """The reservation (worst case) of one request with this content."""
    sizing = size_request(MODEL, provider_messages(make_request(0, content).messages), cfg.generation_params(None, None, False))
    worst = worst_case_pico(PRICE, sizing)
    assert worst is not None
    return worst


def journal(run_dir) -> list[dict]:
    return [json.loads(line) for line in (run_dir / JOURNAL_NAME).read_text().splitlines() if line.strip()]


def one_call(gw: DeploymentGateway, content: str):
    async def go():
        try:
            return await gw.complete(make_request(0, content))
        except LLMError as exc:
            return exc
        finally:
            await gw.aclose()

    return asyncio.run(go())


@pytest.mark.parametrize("mode", UNREADABLE_MODES)
def test_an_unusable_200_is_a_billed_server_error_retried_then_failed(fake_server, run_dir, mode):
    server = fake_server()
    cfg = config(server, max_attempts=3)
    content = f"question FAKE:{mode}"
    err = one_call(DeploymentGateway(cfg, run_dir=run_dir, run_cap_usd=1.0), content)
    worst = worst_of(content, cfg)
    assert isinstance(err, LLMError) and (err.kind, err.retries) == ("server_error", 2), err
    assert [(c.status, c.mode) for c in server.log] == [(200, mode)] * 3
    # each attempt is charged at its reservation: the provider answered (and may have billed) it
    assert err.cost_usd == pico_to_usd(3 * worst) > 0
    settles = [(e["status"], e["pico"]) for e in journal(run_dir) if e["op"] == "settle"]
    assert settles == [("charged", worst)] * 3
    (row,) = table(run_dir, "llm_calls")
    assert (row["status"], row["error_kind"], row["retries"], row["cost_usd"]) == ("error", "server_error", 2, err.cost_usd)
    assert journal_spend((run_dir / JOURNAL_NAME).read_bytes()).spent_usd == row["cost_usd"]
    assert [e["detail"]["kind"] for e in events(run_dir, "retry")] == ["server_error"] * 2
    (failed,) = events(run_dir, "call_failed")
    assert failed["detail"]["kind"] == "server_error" and failed["detail"]["status"] == 200


@pytest.mark.parametrize("mode", UNREADABLE_MODES)
def test_an_unusable_200_once_is_retried_to_an_answer_and_both_attempts_are_charged(fake_server, run_dir, mode):
    server = fake_server()
    cfg = config(server, max_attempts=3)
    content = f"question FAKE:{mode}*1"
    resp = one_call(DeploymentGateway(cfg, run_dir=run_dir), content)
    assert not isinstance(resp, LLMError) and resp.retries == 1 and resp.text.startswith('{"think"')
    second = server.log[1]
    answer = PRICE.cost_pico(second.prompt_tokens, second.cached_tokens, second.completion_tokens)
    assert resp.cost_usd == pico_to_usd(worst_of(content, cfg) + answer)
    assert [e["status"] for e in journal(run_dir) if e["op"] == "settle"] == ["charged", "ok"]


def test_a_good_reply_under_a_wrong_content_type_is_read_and_charged_as_usual(fake_server, run_dir):
    server = fake_server()
    resp = one_call(DeploymentGateway(config(server), run_dir=run_dir), "question FAKE:textplain")
    assert not isinstance(resp, LLMError) and resp.retries == 0 and resp.token_count_source == "provider"
    assert resp.cost_usd == pico_to_usd(true_bill_pico(server)) > 0


@pytest.mark.parametrize("mode", ["500", "503"])
def test_a_real_provider_error_status_is_not_charged(fake_server, run_dir, mode):
    server = fake_server()
    err = one_call(DeploymentGateway(config(server), run_dir=run_dir), f"question FAKE:{mode}")
    assert isinstance(err, LLMError) and err.kind == "server_error" and err.cost_usd == 0.0
    assert {e["status"] for e in journal(run_dir) if e["op"] == "settle"} == {"error"}


@pytest.mark.parametrize("mode", UNREADABLE_MODES)
def test_a_provider_that_answers_only_unusable_200s_cannot_pass_the_cap(fake_server, run_dir, mode):
    """Before, each such reply was charged $0, so the cap never bound and the provider's bill grew
    without limit; now the ledger and the provider's own bill both stay within the cap."""
    server = fake_server()
    cap = 0.001
    gw = DeploymentGateway(config(server), run_dir=run_dir, run_cap_usd=cap)
    out, stats = spend_until_refused(gw, lambda i: f"question {i:03d} FAKE:{mode}")
    assert isinstance(out[-1], LLMError) and out[-1].kind == "budget" and len(out) < 20
    assert {e.kind for e in out[:-1]} == {"server_error"} and all(e.cost_usd > 0 for e in out[:-1])
    bill = true_bill_pico(server)
    assert 0 < bill <= stats["spent_pico"] <= cap * 1e12
    assert stats["reserved_usd"] == 0 and stats["overruns"] == 0


def test_a_provider_whose_usage_keeps_being_impossible_is_no_longer_called(fake_server, run_dir):
    server = fake_server()
    cfg = config(server, max_usage_rejections=2)
    assert config(server).max_usage_rejections == 3  # the default
    gw = DeploymentGateway(cfg, run_dir=run_dir, run_cap_usd=1.0)

    async def go():
        out = []
        for i in range(4):
            try:
                out.append(await gw.complete(make_request(i, f"question {i} FAKE:negusage")))
            except LLMError as exc:
                out.append(exc)
        stats = gw.stats()
        await gw.aclose()
        return out, stats

    out, stats = asyncio.run(go())
    assert [isinstance(r, LLMError) for r in out] == [False, False, True, True]
    assert len(server.log) == 2  # the refused calls never reached the provider
    for err in out[2:]:
        assert err.kind == "budget" and err.refusal is not None
        assert (err.refusal.scope, err.refusal.model, err.refusal.rejected) == ("usage", cfg.deployment_name, 2)
        assert err.message == (
            f"{cfg.deployment_name}: provider usage rejected as impossible in 2 replies "
            "(each charged at its worst case); no more calls to it this session"
        )
    assert stats["calls"]["usage_rejected"] == 2 and stats["calls"]["usage_refused"] == 2
    assert len(events(run_dir, "usage_rejected")) == 2
