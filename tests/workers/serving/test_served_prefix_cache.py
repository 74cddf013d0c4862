"""Prefix caching of a served model, recorded like a provider's cache hits: the test-double engine
(workers/serving/test_double.py) reports the prompt tokens of the prefix a replica has seen as
``usage.prompt_tokens_details.cached_tokens`` (as vLLM's automatic prefix caching does), and the
gateway writes them to ``llm_calls.cached_prompt_tokens``. The replica's class is served here
by uvicorn on loopback, without Ray: the gateway calls it over HTTP as it calls a Serve route.

Traffic (token counts by the documented estimate: 3 + ceil(chars / 4) per message, + 3 per
prompt): a pin of 4800 chars (1203 tokens), a task of 400 chars (103 tokens), then (assistant,
user) turns of 40 chars each (13 tokens each)."""

from __future__ import annotations

import asyncio
import socket
import threading
import time
from collections.abc import Iterator

import pytest

from recap.llm import ChatMessage, LLMRequest
from schemas.parts import read_table
from workers.gateway.core import DeploymentGateway
from workers.llm.providers import DeploymentConfig
from workers.serving.test_double import PrefixCache, TestDoubleServer

PIN, TASK = ChatMessage("user", "A" * 4800), ChatMessage("user", "B" * 400)


def conversation(turns: int) -> tuple[ChatMessage, ...]:
    out = [PIN, TASK]
    for i in range(turns):
        out += [ChatMessage("assistant", "r" * 40), ChatMessage("user", f"{i:02d}" * 20)]
    return tuple(out)


@pytest.fixture
def replica() -> Iterator[str]:
    """One test-double replica on a loopback port; its OpenAI base URL."""
    import uvicorn
    from starlette.requests import Request

    server = TestDoubleServer("offline/expert")

    async def app(scope, receive, send):  # the replica's __call__, as Serve's proxy calls it
        if scope["type"] == "http":
            await (await server(Request(scope, receive)))(scope, receive, send)

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    web = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="error", lifespan="off"))
    thread = threading.Thread(target=web.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 20
    while not web.started and time.monotonic() < deadline:
        time.sleep(0.02)
    assert web.started
    yield f"http://127.0.0.1:{port}/v1"
    web.should_exit = True
    thread.join(10)


def test_the_prefix_a_replica_has_seen_is_reported_cached_message_by_message():
    cache = PrefixCache()
    msgs = [{"role": m.role, "content": m.content} for m in conversation(2)]
    assert cache.cached_tokens(msgs[:2]) == 0
    assert cache.cached_tokens(msgs) == 1203 + 103  # the pin and the task (3 + chars / 4 each)
    assert cache.cached_tokens(msgs) == 1306 + 4 * 13  # all of it (a retry)
    changed = [dict(msgs[0], content="C" * 4800), *msgs[1:]]
    assert cache.cached_tokens(changed) == 0  # a prefix that differs in its first message: nothing


def test_served_cached_prompt_tokens_land_in_llm_calls_like_a_providers_cache_hits(replica, run_dir):
    cfg = DeploymentConfig(model="offline/expert", api_base=replica, max_attempts=1, params={"max_tokens": 20})
    gw = DeploymentGateway(cfg, run_dir=run_dir)

    async def go():
        calls = [LLMRequest(messages=conversation(t), episode_id="ep", call_index=t, purpose="task") for t in range(3)]
        calls.append(LLMRequest(messages=conversation(1), episode_id="ep2", call_index=0, purpose="task"))
        out = [await gw.complete(r) for r in calls]
        await gw.aclose()
        return out

    got = asyncio.run(go())
    rows = sorted(read_table(run_dir, "llm_calls")[0].to_pylist(), key=lambda r: (r["episode_id"], r["call_index"]))
    # each call re-sends the one before it: the pin and task (1306), then those and a turn (1332);
    # another episode's call with the same pin, task and turn reads all but the reply priming
    assert [(r["episode_id"], r["prompt_tokens"], r["cached_prompt_tokens"], r["cache_write_tokens"]) for r in rows] == [
        ("ep", 1309, 0, 0),
        ("ep", 1335, 1306, 0),
        ("ep", 1361, 1332, 0),
        ("ep2", 1335, 1332, 0),
    ]
    assert [g.cached_prompt_tokens for g in got] == [0, 1306, 1332, 1332]
    assert {r["token_count_source"] for r in rows} == {"provider"} and {r["test_double"] for r in rows} == {True}
