"""The Ray-free LiteLLMClient, and the fake server's own behaviour seen over plain HTTP."""

from __future__ import annotations

import httpx
import pytest

from recap.llm import LLMError
from tests.doubles.llm_requests import make_request
from workers.llm.direct import LiteLLMClient
from workers.llm.providers import DeploymentConfig


def test_direct_client_prices_retries_and_classifies_like_the_gateway(fake_server):
    server = fake_server()
    records = []
    client = LiteLLMClient(
        DeploymentConfig(
            model="openai/fake-gpt", api_base=server.base_url, max_attempts=3, backoff_initial_s=0.01, params={"max_tokens": 20}
        ),
        record_sink=records.append,
    )
    resp = client.complete(make_request(0, "hello there"))
    # estimate: 3 + 3 + ceil(11/4) = 9 prompt tokens; 12 completion tokens ($1/M in, $2/M out)
    assert (resp.prompt_tokens, resp.completion_tokens, resp.token_count_source) == (9, 12, "provider")
    assert resp.cost_usd == (9 * 1 + 12 * 2) / 1e6 and resp.test_double
    assert client.complete(make_request(1, "FAKE:503*1")).retries == 1
    with pytest.raises(LLMError) as err:
        client.complete(make_request(2, "FAKE:ctx"))
    assert err.value.kind == "context_length"
    assert [(r.call_key, r.status, r.error_kind) for r in records] == [
        ("ep#0", "ok", None),
        ("ep#1", "ok", None),
        ("ep#2", "error", "context_length"),
    ]


def _chat(url: str, content: str, max_tokens: int = 20, key: str = "k") -> httpx.Response:
    return httpx.post(
        f"{url}/chat/completions",
        headers={"Authorization": f"Bearer {key}"},
        json={"model": "fake-gpt", "max_tokens": max_tokens, "messages": [{"role": "user", "content": content}]},
    )


def test_fake_server_quota_context_limit_and_faults(fake_server):
    server = fake_server(rpm=2, window_s=30, max_context_tokens=50, reply='{"action": "wait"}')
    url = server.base_url
    ok = _chat(url, "hi").json()
    assert ok["choices"][0]["message"]["content"] == '{"action": "wait"}'
    assert ok["usage"] == {
        "prompt_tokens": 7,
        "completion_tokens": 5,
        "total_tokens": 12,
        "prompt_tokens_details": {"cached_tokens": 0},
    }
    long = _chat(url, "x" * 200)  # 56 prompt tokens + 20 > 50
    assert long.status_code == 400 and long.json()["error"]["code"] == "context_length_exceeded"
    limited = _chat(url, "third")
    assert limited.status_code == 429 and limited.json()["error"]["code"] == "rate_limit_exceeded"
    assert 28 <= int(limited.headers["Retry-After"]) <= 30 and int(limited.headers["retry-after-ms"]) > 28_000
    assert [c.status for c in server.log] == [200, 400, 429]


def test_fake_server_directives_truncation_and_cached_prefix(fake_server):
    server = fake_server(reply="word " * 40)  # 200 chars: 50 tokens
    url = server.base_url
    assert _chat(url, "a FAKE:500*1").status_code == 500
    second = _chat(url, "a FAKE:500*1")
    assert second.status_code == 200
    body = second.json()
    assert body["choices"][0]["finish_reason"] == "length" and body["usage"]["completion_tokens"] == 20
    assert _chat(url, "b FAKE:malformed").content == b'{"id": "chatcmpl-fake", "choices": [{"mess'
    third = _chat(url, "a FAKE:ok, and more").json()
    # longest common prefix with an earlier successful prompt: "user:a FAKE:" = 12 chars -> 3 tokens
    assert third["usage"]["prompt_tokens_details"]["cached_tokens"] == 3
    assert (
        _chat(url, "c FAKE:401", key="sk-secret-123456").json()["error"]["message"]
        == "Incorrect API key provided: sk-secret-123456."
    )


def test_a_request_with_stop_sequences_reaches_the_provider_with_them(fake_server):
    """The FEVER notebooks' calls stop at ``\\nObservation i:`` (React.ipynb cell 4): the stop list
    travels to the provider; a request without one sends none."""
    import dataclasses

    server = fake_server(keep_bodies=True)
    client = LiteLLMClient(DeploymentConfig(model="openai/fake-gpt", api_base=server.base_url, params={"max_tokens": 20}))
    client.complete(dataclasses.replace(make_request(0, "Claim: x\nThought 1:"), stop=("\nObservation 1:",)))
    client.complete(make_request(1, "hello"))
    assert [b.get("stop") for b in server.bodies] == [["\nObservation 1:"], None]
