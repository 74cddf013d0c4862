"""Tool calls from a hostile provider (issue 35 item 6), through litellm's real HTTP client against
the loopback fake server, mode by mode (:data:`HOSTILE_CALL_MODES`): arguments nested 200,000 levels
deep (as a string, and as an object inside the body), 5 MB of arguments, two calls under one id, a
call with a null function, content beside the calls, ``finish_reason: tool_calls`` with no call,
arguments as an object, a 1 MB call id.

A reply that arrived is the model's: never a ``server_error`` (an infrastructure failure a resume
pays for again). At the gateway each mode answers the calls exactly as the model made them (the ones
that cannot run marked with why), the call charged what the provider billed and the run cap held;
the body nested past any JSON reader is the model's ``invalid_reply``, charged at its reservation.
In an episode (ReCAP's tool mode on a toy repository) every call the reply made is in
``tool_calls``, the oversized fields cut to the row's bound with the original length said, and the
episode goes on. The attack table and its helpers are the chaos lab's too
(tests/pipeline/chaos/hostile_calls.py)."""

from __future__ import annotations

import asyncio
import json
from typing import Any

import pytest

from recap.config import ReCAPConfig
from recap.llm import ChatMessage, LLMError, LLMRequest, LLMResponse, ToolCall
from recap.recap_agent import ReCAPAgent
from recap.row_bounds import MAX_ARGUMENTS_CHARS, MAX_NAME_CHARS
from recap.runtime import NOT_RUN
from schemas.labels import infra_failure
from schemas.records import CallRecord, MessageRecord, StepRecord, ToolCallRecord
from tests.recap.toy_repo import TOOLS, ToyRepo
from tests.workers.gateway.test_hostile_provider import config, spend_until_refused, table, true_bill_pico
from workers.gateway.core import DeploymentGateway
from workers.llm.direct import LiteLLMClient
from workers.llm.offline.fake_server import HOSTILE_CALL_MODES
from workers.llm.offline.fake_server.faults import BIG_ARGS_BYTES, BIG_ID_BYTES, DEEP_LEVELS, TEXT_WITH_CALLS

BASH = TOOLS[0]
ID = "call_fake_1_0"  # the fake server's id of the first call of its first reply
FAKE_ARGS = '{"command": "fake"}'  # its placeholder arguments for bash
DEEP = "[" * DEEP_LEVELS + "]" * DEEP_LEVELS
BIG = json.dumps({"command": "x" * BIG_ARGS_BYTES})
BIG_ID = "i" * BIG_ID_BYTES
DEEP_ERROR = f"arguments nest {DEEP_LEVELS} levels deep (at most 64 are read)"
DUP_ERROR = "the call's id repeats an earlier call of the same reply"
NO_FUNCTION = "the call names no function"


def fake(call_id: str = ID, arguments: str = FAKE_ARGS) -> ToolCall:
    return ToolCall.parse(call_id, "bash", arguments)


#: what the model's reply is in each mode: (text, tool calls), or the error kind of the call
EXPECTED: dict[str, tuple[str, tuple[ToolCall, ...]] | str] = {
    "deepargs": ("", (ToolCall(ID, "bash", DEEP, None, DEEP_ERROR),)),
    "deepbody": "invalid_reply",
    "bigargs": ("", (fake(arguments=BIG),)),
    "dupids": ("", (fake(), ToolCall(ID, "bash", FAKE_ARGS, None, DUP_ERROR))),
    "nullfunc": ("", (ToolCall(ID, "", "", None, NO_FUNCTION),)),
    "textandcalls": (TEXT_WITH_CALLS, (fake(),)),
    "nocalls": ("", ()),
    "objargs": ("", (fake(),)),
    "bigid": ("", (fake(call_id=BIG_ID),)),
}
assert tuple(EXPECTED) == HOSTILE_CALL_MODES


def tool_request(i: int, mode: str, episode: str = "ep") -> LLMRequest:
    """A request that offers the bash tool, its last message asking the fake server for ``mode``."""
    return LLMRequest(
        messages=(ChatMessage("user", f"question {i:03d} FAKE:{mode}"),),
        episode_id=episode,
        call_index=i,
        purpose="task",
        tools=(BASH,),
        tool_choice="auto",
    )


def one_hostile_call(server: Any, run_dir: Any, mode: str) -> tuple[LLMResponse | LLMError, dict]:
    """One gateway call in ``mode`` (its answer or error, and the ledger's figures after it)."""
    gw = DeploymentGateway(config(server, params={"max_tokens": 64}), run_dir=run_dir, run_cap_usd=1.0)

    async def go() -> tuple[LLMResponse | LLMError, dict]:
        try:
            out: LLMResponse | LLMError = await gw.complete(tool_request(0, mode))
        except LLMError as exc:
            out = exc
        stats = await gw.budget.stats()
        await gw.aclose()
        return out, stats

    return asyncio.run(go())


def reply_matches(mode: str, out: LLMResponse | LLMError) -> bool:
    """Whether the gateway's answer in ``mode`` is the model's reply :data:`EXPECTED` says."""
    want = EXPECTED[mode]
    if isinstance(want, str):
        return isinstance(out, LLMError) and out.kind == want and out.cost_usd > 0
    return isinstance(out, LLMResponse) and (out.text, out.tool_calls, out.finish_reason) == (*want, "tool_calls")


def spend_hostile(gw: DeploymentGateway, mode: str) -> tuple[list, dict]:
    """Calls in ``mode`` until the run cap refuses one (the cap loop of test_hostile_provider)."""
    return spend_until_refused(gw, lambda i: f"question {i:03d} FAKE:{mode}")


@pytest.mark.parametrize("mode", HOSTILE_CALL_MODES)
def test_a_hostile_reply_is_the_models_answer_recorded_and_charged(fake_server, run_dir, mode):
    server = fake_server()
    out, stats = one_hostile_call(server, run_dir, mode)
    assert reply_matches(mode, out), out
    (call,) = server.log
    assert (call.status, call.mode) == (200, mode)
    (row,) = table(run_dir, "llm_calls")
    # what the provider billed is counted, in the row, the answer and the ledger alike
    assert row["cost_usd"] == out.cost_usd == stats["spent_usd"] > 0 and stats["reserved_usd"] == 0
    assert stats["spent_pico"] >= true_bill_pico(server)
    if mode == "deepbody":  # the model's failure: charged at the reservation, never retried
        assert (row["status"], row["error_kind"], row["retries"]) == ("error", "invalid_reply", 0)
        assert out.message.startswith("the provider's HTTP 200 reply nests deeper than a JSON reader goes")
    else:
        assert (row["status"], row["finish_reason"], row["error_kind"]) == ("ok", "tool_calls", None)


@pytest.mark.parametrize("mode", HOSTILE_CALL_MODES)
def test_a_provider_answering_only_hostile_calls_never_passes_the_cap(fake_server, run_dir, mode):
    server = fake_server()
    cap = 0.002
    gw = DeploymentGateway(config(server, params={"max_tokens": 64}), run_dir=run_dir, run_cap_usd=cap)
    out, stats = spend_hostile(gw, mode)
    assert isinstance(out[-1], LLMError) and out[-1].kind == "budget" and len(out) > 2
    assert {r.kind for r in out if isinstance(r, LLMError)} <= {"budget", "invalid_reply"}
    assert stats["spent_usd"] <= cap and stats["reserved_usd"] == 0 and stats["overruns"] == 0
    assert stats["spent_pico"] >= true_bill_pico(server) > 0


# ---- in an episode: every call in tool_calls, bounded, the episode goes on ----


class HostileRepo(ToyRepo):
    """The toy repository whose first observation asks the fake server for ``mode``: only the
    first request ends with it (later ones end with a tool result or a repair)."""

    def __init__(self, mode: str) -> None:
        super().__init__()
        self.mode = mode

    def _bash(self, command: str) -> tuple[str, int]:
        if len(command) > 10_000:  # the toy's shlex would take minutes over 5 MB
            return "bash: argument list too long", 126
        return super()._bash(command)

    def reset(self):  # type: ignore[no-untyped-def]
        r = super().reset()
        return type(r)(f"{r.observation} FAKE:{self.mode}", r.valid_actions, r.goal)


def cut(text: str, limit: int) -> str:
    return text if len(text) <= limit else text[:limit] + f" [cut: {len(text)} characters in all]"


#: (index, step_index, name, arguments, valid, call_id, message_seq, error, exit_code) of each mode's rows
NOT_FOUND = 127  # the toy repository's answer to ``bash fake``
ROWS: dict[str, list[tuple]] = {
    "deepargs": [(0, 0, "bash", cut(DEEP, MAX_ARGUMENTS_CHARS), False, ID, 1, DEEP_ERROR, None)],
    "deepbody": [],
    "bigargs": [(0, 0, "bash", cut(BIG, MAX_ARGUMENTS_CHARS), True, ID, 1, None, 126)],
    "dupids": [(0, 0, "bash", FAKE_ARGS, True, ID, 1, None, NOT_FOUND), (1, 1, "bash", FAKE_ARGS, False, ID, 1, DUP_ERROR, None)],
    "nullfunc": [(0, 0, "", "", False, ID, 1, NO_FUNCTION, None)],
    "textandcalls": [(0, 0, "bash", FAKE_ARGS, False, ID, 1, NOT_RUN, None)],
    "nocalls": [],
    "objargs": [(0, 0, "bash", FAKE_ARGS, True, ID, 1, None, NOT_FOUND)],
    "bigid": [(0, 0, "bash", FAKE_ARGS, True, cut(BIG_ID, MAX_NAME_CHARS), 1, None, NOT_FOUND)],
}


def hostile_episode(server: Any, mode: str) -> tuple[Any, list[Any], list[CallRecord]]:
    """ReCAP's tool mode on the toy repository, its first reply in ``mode``, two calls at most:
    (the result, the episode's rows, the client's call rows)."""
    rows: list[Any] = []
    billed: list[CallRecord] = []
    client = LiteLLMClient(config(server, params={"max_tokens": 64}, max_attempts=1), record_sink=billed.append)
    agent = ReCAPAgent(ReCAPConfig(window=100, max_llm_calls=2))
    result = agent.run(HostileRepo(mode), client, episode_id="e", emit=rows.append)
    return result, rows, billed


def tool_rows(rows: list[Any]) -> list[tuple]:
    return [
        (r.index, r.step_index, r.name, r.arguments, r.valid, r.call_id, r.message_seq, r.error, r.exit_code)
        for r in rows
        if isinstance(r, ToolCallRecord)
    ]


@pytest.mark.parametrize("mode", HOSTILE_CALL_MODES)
def test_an_episode_records_every_hostile_call_bounded_and_goes_on(fake_server, mode):
    server = fake_server()
    result, rows, billed = hostile_episode(server, mode)
    assert tool_rows(rows) == ROWS[mode]
    assert infra_failure(result.end_reason, result.error) is None  # never infrastructure
    if mode == "deepbody":  # the model's unreadable reply ends the episode as its failure
        assert (result.end_reason, result.error_kind, result.llm_calls) == ("llm_error", "invalid_reply", 1)
    else:  # the episode went on to its call limit
        assert (result.end_reason, result.llm_calls) == ("call_cap", 2)
    assert [c.mode for c in server.log][:1] == [mode] and len(server.log) == result.llm_calls
    # every call paid for is counted: the client's rows, the episode's rows and its cost agree
    calls = [r for r in rows if isinstance(r, CallRecord)]
    assert [c.cost_usd for c in calls] == [c.cost_usd for c in billed] and len(calls) == result.llm_calls
    assert all(c.cost_usd > 0 for c in calls) and result.cost_usd == pytest.approx(sum(c.cost_usd for c in calls), abs=1e-12)
    assert [c.status for c in calls][:1] == ["error" if mode == "deepbody" else "ok"]
    # no row holds more of what the model wrote than the bounds (the cut notes apart)
    bound = MAX_ARGUMENTS_CHARS + 2 * MAX_NAME_CHARS + 200
    for r in rows:
        if isinstance(r, ToolCallRecord):
            assert len(r.arguments) + len(r.name) + len(r.call_id or "") <= bound
        if isinstance(r, StepRecord):
            assert len(r.action) <= MAX_ARGUMENTS_CHARS + 40
        if isinstance(r, MessageRecord) and r.role != "user":  # the prompts hold only our text and observations
            assert len(r.tool_calls or "") <= bound and len(r.tool_call_id or "") <= MAX_NAME_CHARS + 40
