"""The gateway's attempt loop (:meth:`DeploymentGateway._attempts`): the first attempt runs bare,
retries follow tenacity's stop and wait strategies (issue 37 took tenacity off the first attempt).

The attempts are stubbed (no HTTP): what is asserted is the loop itself - how many attempts run,
which failure ends the call, and the ``retry`` events (one per failed attempt that another follows,
numbered from 1), as tenacity's ``AsyncRetrying`` ran them before.
"""

from __future__ import annotations

import asyncio
import time

import pytest

from schemas.kinds import LLMErrorKind
from tests.doubles.llm_requests import make_request
from workers.gateway.call_state import CallState, FinalFailure, Retryable
from workers.gateway.core import DeploymentGateway
from workers.llm.errors import Classified
from workers.llm.providers import DeploymentConfig


def _gateway(run_dir, **kw) -> DeploymentGateway:
    args = dict(
        model="openai/fake-gpt", api_base="http://127.0.0.1:9/v1", max_attempts=3, backoff_initial_s=0.001, backoff_max_s=0.002
    )
    args.update(kw)
    return DeploymentGateway(DeploymentConfig(**args), run_dir=run_dir, run_id="retry-loop")


def _run(gw: DeploymentGateway, outcomes: list, *, attempt_s: float = 0.0) -> tuple[object, list[int], list[tuple[int, str]]]:
    """Run ``_attempts`` over stubbed attempts that raise or return ``outcomes`` in turn; the
    result (or the exception raised), the attempt numbers run, the (attempt, kind) of each retry event."""
    run: list[int] = []
    events: list[tuple[int, str]] = []

    async def one_attempt(call: CallState):
        call.attempts += 1
        run.append(call.attempts)
        if attempt_s:
            await asyncio.sleep(attempt_s)
        out = outcomes[len(run) - 1]
        if isinstance(out, BaseException):
            raise out
        return out

    gw._one_attempt = one_attempt  # type: ignore[method-assign]
    gw._attempt_event = lambda kind, severity, call, c, attempt: events.append((attempt, c.kind)) if kind == "retry" else None  # type: ignore[method-assign]
    call = gw._new_call(make_request(0), gw._clock())
    try:
        result: object = asyncio.run(gw._attempts(call))
    except BaseException as exc:  # noqa: BLE001 - the loop's own outcome is what is asserted
        result = exc
    return result, run, events


def _retryable(kind: LLMErrorKind = "server_error") -> Retryable:
    return Retryable(Classified(kind, f"{kind} from the stub"))


def test_first_attempt_answers_without_retry(run_dir):
    result, run, events = _run(_gateway(run_dir), ["answer"])
    assert (result, run, events) == ("answer", [1], [])


def test_retryable_failures_are_retried_then_answered(run_dir):
    result, run, events = _run(_gateway(run_dir), [_retryable(), _retryable("timeout"), "answer"])
    assert (result, run, events) == ("answer", [1, 2, 3], [(1, "server_error"), (2, "timeout")])


def test_last_attempt_failure_is_raised_as_is(run_dir):
    last = _retryable("rate_limit")
    result, run, events = _run(_gateway(run_dir), [_retryable(), _retryable(), last])
    assert result is last  # reraise=True: the last attempt's own exception, not a RetryError
    assert (run, events) == ([1, 2, 3], [(1, "server_error"), (2, "server_error")])


def test_final_failure_and_cancellation_are_not_retried(run_dir):
    final = FinalFailure(Classified("bad_request", "no"))
    assert _run(_gateway(run_dir / "a"), [final]) == (final, [1], [])  # a gateway per folder (one ledger each)
    assert _run(_gateway(run_dir / "b"), [_retryable(), final])[1:] == ([1, 2], [(1, "server_error")])
    result, run, _ = _run(_gateway(run_dir / "c"), [asyncio.CancelledError()])
    assert isinstance(result, asyncio.CancelledError) and run == [1]


def test_total_time_stops_retries_from_the_first_attempts_start(run_dir):
    """stop_after_delay counts from before the first attempt (tenacity's start), so a first attempt
    that alone outlasts total_timeout_s is not retried, and its own failure ends the call."""
    first = _retryable()
    t0 = time.monotonic()
    result, run, events = _run(_gateway(run_dir, total_timeout_s=0.05), [first, "never"], attempt_s=0.08)
    assert (result, run, events) == (first, [1], [])
    assert time.monotonic() - t0 < 5  # no backoff sleep either


@pytest.mark.parametrize("max_attempts", [1, 2])
def test_max_attempts_bounds_the_attempts(run_dir, max_attempts):
    failures = [_retryable() for _ in range(3)]
    result, run, events = _run(_gateway(run_dir, max_attempts=max_attempts), failures)
    assert result is failures[max_attempts - 1]
    assert run == list(range(1, max_attempts + 1))
    assert events == [(i, "server_error") for i in range(1, max_attempts)]
