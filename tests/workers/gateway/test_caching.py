"""Provider prompt caching: each provider's rule in the fake server, parsed by litellm's real HTTP
client on loopback, priced exactly, and the gateway's cache markers.

Traffic used throughout (token counts by the documented estimate: 3 + ceil(chars / 4) per
message, + 3 per prompt): a pin of 4800 chars (1203 tokens), a task of 400 chars (103 tokens),
then (assistant, user) turns of 40 chars each (13 tokens each). The fake server replies with
40 chars (10 completion tokens).
"""

from __future__ import annotations

import asyncio

import pytest

from recap.llm import ChatMessage, LLMRequest
from schemas.parts import read_table
from workers.gateway.core import DeploymentGateway
from workers.llm.accounting import Sizing, settle, size_request, usage_problems, worst_case_pico
from workers.llm.cache_markers import BreakpointPlanner, with_markers
from workers.llm.calling import Attempt
from workers.llm.direct import LiteLLMClient
from workers.llm.pricing import default_prices
from workers.llm.prompt_cache import Message, PromptCache, openai_cached
from workers.llm.providers import DeploymentConfig

REPLY = "r" * 40
RULES = {"fake-gpt": "openai", "fake-claude": "anthropic", "fake-deepseek": "deepseek"}
PIN, TASK = ChatMessage("user", "A" * 4800), ChatMessage("user", "B" * 400)


def turn(i: int) -> tuple[ChatMessage, ChatMessage]:
    return ChatMessage("assistant", REPLY), ChatMessage("user", f"{i:02d}" * 20)


def conversation(turns: int) -> tuple[ChatMessage, ...]:
    out = [PIN, TASK]
    for i in range(turns):
        out += turn(i)
    return tuple(out)


def usd(uncached: int, read: int = 0, written: int = 0, *, cached_rate: int = 100_000) -> float:
    """The exact bill of one call of the test-double prices ($1/M input, $2/M output, the cached
    rate given, $1.25/M cache writes; 10 completion tokens), as the gateway rounds it."""
    return (uncached * 1_000_000 + read * cached_rate + written * 1_250_000 + 10 * 2_000_000) / 1e12


def request(turns: int, i: int, episode: str = "ep") -> LLMRequest:
    return LLMRequest(messages=conversation(turns), episode_id=episode, call_index=i, purpose="task")


def client(server, model: str, sink: list, **kw) -> LiteLLMClient:
    cfg = DeploymentConfig(model=model, api_base=server.base_url, max_attempts=1, params={"max_tokens": 20}, **kw)
    return LiteLLMClient(cfg, record_sink=sink.append)


@pytest.fixture
def caching_server(fake_server):
    return fake_server(reply=REPLY, keep_bodies=True, cache_rules=RULES)


# ---- each provider's rule through litellm's HTTP client ----------------------------------


def test_openai_rule_reports_1024_plus_128_increments_as_cached_tokens(caching_server):
    rows: list = []
    c = client(caching_server, "openai/fake-gpt", rows)
    got = [c.complete(request(t, t)) for t in range(3)]
    # prompts 1309, 1335, 1361; shared prefixes 1306 (pin + task), 1332 -> 1024 + 2 x 128 = 1280
    assert [(r.prompt_tokens, r.cached_prompt_tokens) for r in got] == [(1309, 0), (1335, 1280), (1361, 1280)]
    assert [(r.cached_prompt_tokens, r.cache_write_tokens) for r in rows] == [(0, 0), (1280, 0), (1280, 0)]
    assert [c.cached_tokens for c in caching_server.log] == [0, 1280, 1280]
    # no markers for an automatic cache: the messages went out as plain strings
    assert all(isinstance(m["content"], str) for b in caching_server.bodies for m in b["messages"])
    # $1/M input, $0.5/M cached, $2/M output
    assert [r.cost_usd for r in got] == [usd(1309), usd(55, 1280, cached_rate=500_000), usd(81, 1280, cached_rate=500_000)]


def test_anthropic_rule_writes_at_marked_breakpoints_and_reads_them_back(caching_server):
    rows: list = []
    c = client(caching_server, "openai/fake-claude", rows)  # explicit_cache in the price table
    got = [c.complete(request(t, t)) for t in range(3)]
    # call 0: nothing seen before, no marker; call 1 marks the end of what it shares with call 0
    # (pin + task, 1306 tokens) and writes it; call 2 reads it and writes the next turn (26)
    assert [(r.prompt_tokens, r.cached_prompt_tokens, w.cache_write_tokens) for r, w in zip(got, rows)] == [
        (1309, 0, 0),
        (1335, 0, 1306),
        (1361, 1306, 26),
    ]
    sent = [[isinstance(m["content"], list) for m in b["messages"]] for b in caching_server.bodies]
    assert sent == [[False, False], [False, True, False, False], [False, True, False, True, False, False]]
    block = caching_server.bodies[1]["messages"][1]["content"]
    assert block == [{"type": "text", "text": "B" * 400, "cache_control": {"type": "ephemeral"}}]
    # $1/M input, $0.1/M read, $1.25/M write, $2/M output
    assert [r.cost_usd for r in got] == [usd(1309), usd(29, 0, 1306), usd(29, 1306, 26)]


def test_deepseek_rule_hits_the_unit_ending_after_the_previous_reply(caching_server):
    rows: list = []
    c = client(caching_server, "openai/fake-deepseek", rows)
    got = [c.complete(request(t, t)) for t in range(3)]
    # call 1 matches the unit "call 0's prompt + its reply" (1306 + 13 = 1319 tokens) completely
    assert [(r.prompt_tokens, r.cached_prompt_tokens) for r in got] == [(1309, 0), (1335, 1319), (1361, 1345)]
    assert [w.cache_write_tokens for w in rows] == [0, 0, 0]
    assert [r.cost_usd for r in got] == [usd(1309), usd(16, 1319), usd(16, 1345)]


@pytest.mark.parametrize(
    "rule, fields",
    [
        ("openai", {"prompt_tokens_details": {"cached_tokens": 1280}}),
        ("anthropic", {"cache_read_input_tokens": 1306, "cache_creation_input_tokens": 26}),
        # the first answer's unit (its prompt + its reply, 1319 tokens) matches completely
        ("deepseek", {"prompt_cache_hit_tokens": 1319, "prompt_cache_miss_tokens": 29}),
    ],
)
def test_each_rule_answers_in_its_providers_own_usage_fields(fake_server, rule, fields):
    import httpx

    server = fake_server(reply=REPLY, cache_rule=rule)

    def post(messages):
        body = {"model": "m", "max_tokens": 20, "messages": messages}
        return httpx.post(f"{server.base_url}/chat/completions", json=body).json()["usage"]

    plain = [m.as_dict() for m in conversation(1)]
    post(with_markers(plain[:2], [1]))  # writes pin + task under the anthropic rule
    usage = post(with_markers([*plain, {"role": "user", "content": "x" * 40}], [1, 3]))
    assert {k: usage[k] for k in fields} == fields
    assert usage["prompt_tokens"] == 1348
    others = {
        "prompt_tokens_details",
        "cache_read_input_tokens",
        "cache_creation_input_tokens",
        "prompt_cache_hit_tokens",
        "prompt_cache_miss_tokens",
    } - set(fields)
    assert not others & set(usage)


def test_idle_episodes_lose_their_cache_after_the_ttl(caching_server):
    rows: list = []
    c = client(caching_server, "openai/fake-claude", rows)
    for t in range(3):
        c.complete(request(t, t))
    caching_server.advance(299)  # within 5 minutes of the last read: still cached
    c.complete(request(3, 3))
    caching_server.advance(301)  # idle past the TTL: everything is written again
    c.complete(request(4, 4))
    assert [(r.cached_prompt_tokens, r.cache_write_tokens) for r in rows[3:]] == [(1332, 26), (0, 1384)]


def test_cache_markers_can_be_turned_off(caching_server):
    rows: list = []
    c = client(caching_server, "openai/fake-claude", rows, cache_markers=False)
    for t in range(3):
        c.complete(request(t, t))
    assert all(isinstance(m["content"], str) for b in caching_server.bodies for m in b["messages"])
    assert [(r.cached_prompt_tokens, r.cache_write_tokens) for r in rows] == [(0, 0)] * 3


def test_gateway_marks_breakpoints_and_records_cache_writes(caching_server, run_dir):
    cfg = DeploymentConfig(
        model="openai/fake-claude", api_base=caching_server.base_url, max_attempts=1, params={"max_tokens": 20}
    )
    gw = DeploymentGateway(cfg, run_dir=run_dir)

    async def go():
        out = [await gw.complete(request(t, t)) for t in range(3)]
        await gw.aclose()
        return out

    got = asyncio.run(go())
    rows = sorted(read_table(run_dir, "llm_calls")[0].to_pylist(), key=lambda r: r["call_index"])
    assert [(r["prompt_tokens"], r["cached_prompt_tokens"], r["cache_write_tokens"]) for r in rows] == [
        (1309, 0, 0),
        (1335, 0, 1306),
        (1361, 1306, 26),
    ]
    assert [r["cost_usd"] for r in rows] == [g.cost_usd for g in got]
    assert rows[2]["cost_usd"] == usd(29, 1306, 26)


# ---- breakpoints under pair and block windowing -------------------------------------------


def _window(pins: list[str], live: list[str]) -> list[dict]:
    return [{"role": "user", "content": c} for c in pins + live]


def test_breakpoints_end_the_pins_under_pair_trimming_and_the_stable_block_under_block():
    pins = ["demo", "task"]
    pair = BreakpointPlanner()
    # pair trimming with a 4-message window: the window shifts by two on every call
    calls = [["a", "b"], ["a", "b", "c", "d"], ["c", "d", "e", "f"], ["e", "f", "g", "h"]]
    assert [pair.plan("ep", _window(pins, live)) for live in calls] == [(), (3,), (1,), (1,)]
    block = BreakpointPlanner()
    # block trimming: the window grows until a block of 4 is dropped, then grows again
    calls = [
        ["a", "b"],
        ["a", "b", "c", "d"],
        ["a", "b", "c", "d", "e", "f"],
        ["e", "f", "g", "h"],
        ["e", "f", "g", "h", "i", "j"],
    ]
    # the longest shared prefix and the shortest one (kept across the next trim)
    assert [block.plan("ep", _window(pins, live)) for live in calls] == [(), (3,), (3, 5), (1,), (1, 5)]
    # another episode's history does not count
    assert block.plan("other", _window(pins, ["e", "f"])) == ()


def test_two_breakpoints_when_the_last_requests_share_different_prefixes():
    planner = BreakpointPlanner()
    planner.plan("ep", _window(["demo", "task"], ["x", "y"]))
    planner.plan("ep", _window(["demo", "task"], ["a", "b"]))
    assert planner.plan("ep", _window(["demo", "task"], ["a", "b", "c", "d"])) == (1, 3)


# ---- the rules without HTTP ----------------------------------------------------------------


def test_openai_increments_and_minimum():
    assert [openai_cached(n) for n in (0, 1023, 1024, 1151, 1152, 5000)] == [0, 0, 1024, 1024, 1152, 4992]


def test_anthropic_lookback_reaches_only_20_blocks_before_a_breakpoint():
    msgs = [Message("user", f"m{i}") for i in range(30)]  # 4 tokens each

    def marked_at(n: int) -> list[Message]:
        return [*msgs[:n], Message("user", f"m{n}", True)]

    for last, expected in ((24, (20, 80)), (25, (0, 104))):
        cache = PromptCache("anthropic", min_tokens=0)
        assert cache.serve("m", marked_at(4), 0.0).cache_write_tokens == 20
        out = cache.serve("m", marked_at(last), 1.0)  # the entry ends 20 / 21 blocks earlier
        assert (out.cached_tokens, out.cache_write_tokens) == expected


def test_anthropic_prefix_below_the_minimum_is_not_cached():
    cache = PromptCache("anthropic")  # 1024 tokens
    short = [Message("user", "x" * 400, True)]
    assert cache.serve("m", short, 0.0).cache_write_tokens == 0
    assert cache.serve("m", short, 1.0).cached_tokens == 0


# ---- accounting ----------------------------------------------------------------------------


def _sizing(prompt: int, max_tokens: int = 20) -> Sizing:
    messages = [{"role": "user", "content": "x" * (4 * (prompt - 6))}]
    return size_request("openai/fake-claude", messages, {"max_tokens": max_tokens})


def test_cache_writes_are_checked_and_priced_at_the_write_price():
    price = default_prices().get("openai/fake-claude")
    sizing = _sizing(1000)
    assert sizing.counted.tokens == 1000

    def attempt(cached, written):
        return Attempt(
            text=REPLY,
            finish_reason="stop",
            prompt_tokens=1000,
            cached_prompt_tokens=cached,
            completion_tokens=10,
            litellm_cost_usd=None,
            cache_write_tokens=written,
        )

    ok = settle("openai/fake-claude", price, attempt(600, 300), sizing)
    assert not ok.rejected and ok.usage.cache_write_tokens == 300
    assert ok.cost_pico == 100 * 1_000_000 + 600 * 100_000 + 300 * 1_250_000 + 10 * 2_000_000
    assert usage_problems(attempt(600, -1), sizing, 10) == ["cache-write prompt tokens -1 is negative"]
    assert usage_problems(attempt(600, 401), sizing, 10) == [
        "cached 600 + cache-write 401 prompt tokens above prompt_tokens 1000"
    ]


def test_worst_case_reserves_every_prompt_token_at_the_write_price():
    price = default_prices().get("openai/fake-claude")
    sizing = _sizing(1000)
    assert worst_case_pico(price, sizing) == sizing.prompt_bound * 1_250_000 + (20 + 2) * 2_000_000
    gpt = default_prices().get("openai/fake-gpt")  # no write surcharge: the input price
    assert worst_case_pico(gpt, sizing) == sizing.prompt_bound * 1_000_000 + (20 + 2) * 2_000_000
