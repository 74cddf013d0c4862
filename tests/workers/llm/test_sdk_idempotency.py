"""The OpenAI SDK makes no random idempotency key for a client that never sends one
(:mod:`workers.llm.sdk_idempotency`); a client with an idempotency header still sends a fresh key."""

from __future__ import annotations

import uuid

import httpx
from openai import AsyncOpenAI
from openai._models import FinalRequestOptions

from tests.workers.llm.fake_calls import fake_call
from workers.llm import sdk_idempotency
from workers.llm.litellm_setup import get_litellm

litellm = get_litellm()  # installs the wrapper with the rest of the litellm setup


def _headers(client: AsyncOpenAI, key: str) -> httpx.Headers:
    """The headers the client would send with a request carrying ``key`` (case-insensitive)."""
    options = FinalRequestOptions.construct(method="post", url="/chat/completions", json_data={}, idempotency_key=key)
    return client._build_headers(options, retries_taken=0)


def test_no_key_without_a_header_and_a_fresh_sent_key_with_one() -> None:
    assert sdk_idempotency.install() is True
    plain = AsyncOpenAI(api_key="k", base_url="http://127.0.0.1:9/v1")
    assert plain._idempotency_header is None
    assert plain._idempotency_key() == sdk_idempotency.UNSENT_KEY
    assert sdk_idempotency.UNSENT_KEY not in _headers(plain, plain._idempotency_key()).values()  # never sent

    sending = AsyncOpenAI(api_key="k", base_url="http://127.0.0.1:9/v1")
    sending._idempotency_header = "Idempotency-Key"
    first, second = sending._idempotency_key(), sending._idempotency_key()
    assert first != second and first.startswith("stainless-python-retry-") and first != sdk_idempotency.UNSENT_KEY
    assert _headers(sending, first)["Idempotency-Key"] == first


def test_a_litellm_call_makes_no_uuid_in_the_sdk(fake_server, monkeypatch) -> None:
    import openai._base_client as base_client

    made: list[uuid.UUID] = []

    class CountingUuid:
        @staticmethod
        def uuid4() -> uuid.UUID:
            made.append(uuid.uuid4())
            return made[-1]

    monkeypatch.setattr(base_client, "uuid", CountingUuid)
    server = fake_server()
    resp = fake_call(server.base_url)
    assert resp.choices[0].message.content  # the call is answered as before
    assert made == []
