"""The served test double's answer (workers/serving/test_double.py) and the offline provider
forwarding to it over HTTP (workers/llm/offline/remote.py): the same reply, tool calls and usage
as the in-process test double, and a replica's failure classified as a retryable server error."""

from __future__ import annotations

import asyncio
import json
from typing import Any

from aiohttp import web

from workers.llm.errors import classify
from workers.llm.litellm_setup import get_litellm
from workers.llm.offline.provider import offline_reply
from workers.llm.offline.wire import OFFLINE_METADATA_KEY
from workers.serving.test_double import chat_answer

HINTS = {"reply_fields": ["think", "action"], "expert_plan": ["unstack B from A", "put down B"]}
MESSAGES = [{"role": "system", "content": "you act"}, {"role": "user", "content": "the blocks"}]


def test_the_served_answer_is_the_in_process_test_double_answer_with_its_usage():
    meta = {OFFLINE_METADATA_KEY: {"call_key": "k1", "hints": HINTS, "options": {}}}
    body = {"model": "offline/expert", "messages": MESSAGES, OFFLINE_METADATA_KEY: meta[OFFLINE_METADATA_KEY]}
    got = chat_answer(body)
    local = offline_reply("expert", MESSAGES, meta, None)
    assert got["choices"][0]["message"] == {"role": "assistant", "content": local.text}
    assert json.loads(local.text)["action"] == "unstack B from A"
    assert got["choices"][0]["finish_reason"] == "stop" and got["model"] == "offline/expert"
    assert (
        got["usage"]["prompt_tokens"] > 0
        and got["usage"]["total_tokens"] == got["usage"]["prompt_tokens"] + got["usage"]["completion_tokens"]
    )


async def _serve(fail_first: int) -> tuple[web.AppRunner, str, list[dict[str, Any]]]:
    seen: list[dict[str, Any]] = []
    left = {"n": fail_first}

    async def chat(request: web.Request) -> web.StreamResponse:
        body = await request.json()
        seen.append(body)
        if left["n"] > 0:
            left["n"] -= 1
            return web.Response(status=500, text="the replica died")
        return web.json_response(chat_answer(body))

    app = web.Application()
    app.router.add_post("/r/v1/chat/completions", chat)
    runner = web.AppRunner(app)
    await runner.setup()
    site = web.TCPSite(runner, "127.0.0.1", 0)
    await site.start()
    port = site._server.sockets[0].getsockname()[1]  # type: ignore[union-attr]
    return runner, f"http://127.0.0.1:{port}/r/v1", seen


def test_the_offline_provider_forwards_to_a_served_copy_and_a_5xx_is_a_server_error():
    litellm = get_litellm()

    async def run() -> tuple[Any, Any, list[dict[str, Any]]]:
        runner, base, seen = await _serve(fail_first=1)
        kwargs = {
            "model": "offline/expert",
            "messages": MESSAGES,
            "api_base": base,
            "num_retries": 0,
            "metadata": {OFFLINE_METADATA_KEY: {"call_key": "k1", "hints": HINTS, "options": {}}},
        }
        try:
            try:
                await litellm.acompletion(**kwargs)
                failed = None
            except Exception as exc:  # the first arrival: HTTP 500
                failed = classify(exc)
            return failed, await litellm.acompletion(**kwargs), seen
        finally:
            await runner.cleanup()

    failed, resp, seen = asyncio.run(run())
    assert failed is not None and (failed.kind, failed.status_code) == ("server_error", 500)
    # the hints travelled in the body (only to a served test double), and the answer is the expert's
    assert [b[OFFLINE_METADATA_KEY]["hints"] for b in seen] == [HINTS, HINTS]
    assert json.loads(resp.choices[0].message.content)["action"] == "unstack B from A"
    assert resp.model == "offline/expert" and resp.usage.prompt_tokens > 0


def test_an_unreachable_served_copy_is_a_server_error():
    litellm = get_litellm()

    async def run() -> Any:
        try:
            await litellm.acompletion(
                model="offline/expert", messages=MESSAGES, api_base="http://127.0.0.1:9/v1", num_retries=0, metadata={}
            )
        except Exception as exc:
            return classify(exc)
        return None

    got = asyncio.run(run())
    assert got is not None and (got.kind, got.status_code) == ("server_error", 503)
