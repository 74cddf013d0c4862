"""Units that ended in an infrastructure failure are not done (no Ray): which rows count as one,
what resume queues (the next attempt, a fresh count of failed attempts), what ``recap status``
says, and the driver's exit status."""

from __future__ import annotations

import json

import pytest

from pipeline.cli import main
from pipeline.driver import EXIT_INFRA, RunSummary
from pipeline.resume import UnitQueue, infra_failure, is_final, load_state
from pipeline.spec import parse_spec
from pipeline.store import RunStore
from pipeline.summary import collect
from pipeline.units import expand
from schemas.parts import PartWriter
from schemas.records import EpisodeRecord, EventRecord

SPEC = """run: infra
output: {out}
models: [{{model: offline/expert}}]
methods: [{{method: react}}]
environments: [{{benchmark: blocksworld, tasks: ["3"]}}]
"""


@pytest.mark.parametrize(
    "reason, error, kind",
    [
        ("llm_error", "server_error: APIConnectionError: Connection refused (http://127.0.0.1:9/v1)", "server_error"),
        ("llm_error", "auth: AuthenticationError: invalid api key", "auth"),
        ("llm_error", "rate_limit: Retry-After 3600s is longer than the deployment waits", "rate_limit"),
        ("llm_error", "timeout: gateway gpt gave no answer within 120s", "timeout"),
        ("llm_error", "bad_request: NotFoundError: litellm.NotFoundError: 404 page not found", "not_found"),
        ("llm_error", "context length exceeded with nothing left to drop", None),
        ("llm_error", "bad_request: BadRequestError: temperature must be <= 2", None),
        ("env_error", "gave up after 3 failed attempts (infrastructure: worker_lost); last: ActorDiedError: x", "worker_lost"),
        ("llm_error", "gave up after 3 failed attempts (infrastructure: client); last: client: ClientError: x", "client"),
        ("env_error", "gave up after 3 failed attempts; last: ActorDiedError: The actor died", "worker_lost"),  # older rows
        ("env_error", "gave up after 3 failed attempts; last: agent: KeyError: 'x'", None),
        ("env_error", "FileNotFoundError: no such game", None),
        ("success", None, None),
        ("budget_exhausted", "run budget spent", None),
    ],
)
def test_which_rows_are_infrastructure_failures(reason, error, kind):
    assert infra_failure(reason, error) == kind
    assert is_final(reason, error) == (kind is None and reason != "budget_exhausted")


def _ep(uid: str, attempt: int, reason: str, error: str | None = None) -> EpisodeRecord:
    return EpisodeRecord(
        f"{uid}-{attempt}",
        uid,
        attempt,
        "blocksworld",
        "",
        "",
        "x",
        0,
        "react",
        "{}",
        "offline/expert",
        reason,
        reason == "success",
        0,
        0,
        0,
        0,
        0,
        0.0,
        0.0,
        0,
        4.0,
        error=error,
    )


def _folder(tmp_path):
    out = tmp_path / "run"
    text = SPEC.format(out=out)
    plan = expand(parse_spec(text))
    store = RunStore(out)
    store.create_identity("infra")
    store.write_text("spec.yaml", text)
    store.write_text("plan.json", plan.to_json())
    return out, plan, store


def test_resume_queues_failed_units_under_the_next_attempt_with_a_fresh_failure_count(tmp_path):
    out, plan, store = _folder(tmp_path)
    a, b, c = (u.unit_id for u in plan.units)
    w = PartWriter(out, "t")
    w.write_records(
        "r",
        [
            _ep(a, 1, "success"),
            _ep(b, 1, "llm_error", "server_error: APIConnectionError: Connection refused"),
            _ep(c, 3, "env_error", "gave up after 3 failed attempts (infrastructure: worker_lost); last: ActorDiedError"),
            *[EventRecord(1.0, "driver", "worker_lost", unit_id=c, detail=json.dumps({"attempt": n})) for n in (1, 2, 3)],
        ],
    )
    state = load_state(store)
    assert state.completed == {a}
    assert state.infra_failed == {b: "server_error", c: "worker_lost"}
    assert state.failures == {}  # the give-up row spent them: a retry gets max_attempts again
    q = UnitQueue(plan.units, state)
    got = sorted((p.unit.unit_id, p.attempt) for p in (q.take(), q.take()))
    assert got == sorted([(b, 2), (c, 4)]) and q.take() is None

    report = collect(store)
    assert (report.completed, report.failed, report.failed_kinds) == (1, 2, {"server_error": 1, "worker_lost": 1})
    assert main(["status", str(out)]) == 0

    # the retry succeeded: done, and the earlier row stays for the record
    w.write_records("r", [_ep(b, 2, "success"), _ep(c, 4, "success")])
    state = load_state(store)
    assert state.completed == {a, b, c} and state.infra_failed == {}
    assert collect(store).failed == 0


def test_status_says_how_many_failed_and_how_to_retry(tmp_path, capsys):
    out, plan, _ = _folder(tmp_path)
    a, b, c = (u.unit_id for u in plan.units)
    PartWriter(out, "t").write_records(
        "r",
        [
            _ep(a, 1, "success"),
            _ep(b, 1, "llm_error", "auth: AuthenticationError: bad key"),
            _ep(c, 1, "llm_error", "auth: AuthenticationError: bad key"),
        ],
    )
    assert main(["status", str(out)]) == 0
    text = capsys.readouterr().out
    assert "units 1/3 done, 1 succeeded, 0 stopped by a budget cap, 2 failed on infrastructure, 0 not finished" in text
    assert f"2 units ended in an infrastructure failure (auth 2); fix the cause, then retry them with: recap resume {out}" in text


def test_exit_status_of_a_session_with_infrastructure_failures():
    s = RunSummary(
        location="/r",
        run="r",
        run_id="x",
        total=3,
        completed_before=1,
        finished_now=1,
        infra_failed=1,
        infra_kinds={"server_error": 1},
    )
    assert s.exit_code() == EXIT_INFRA == 4
    assert s.retry_hint() == (
        "1 unit ended in an infrastructure failure (server_error 1); fix the cause, then retry them with: recap resume /r"
    )
    s.interrupted = True
    assert s.exit_code() == 130
    done = RunSummary(location="/r", run="r", run_id="x", total=2, completed_before=1, finished_now=1)
    assert (done.exit_code(), done.retry_hint()) == (0, None)
    capped = RunSummary(location="/r", run="r", run_id="x", total=2, completed_before=1)
    assert capped.exit_code() == 3
