"""A provider whose tool calls are hostile, through the real CLI on a local Ray with a coding
sweep (ReCAP's tool-call mode, a local sandbox) - issue 35 item 6:

* every reply makes a call whose arguments are nested 200,000 levels deep. Before, litellm failed
  reading the reply (``RecursionError`` in its tool-call helper), the call was a ``server_error``
  and the unit ended ``infra_error``, which every ``recap resume`` ran, and paid for, again. Now
  the reply is the model's: each call is recorded in ``tool_calls`` (invalid, its arguments cut
  to the row's bound with the original length said), answered as invalid, and the episode goes
  on to its call limit; ``recap resume`` finds nothing to do and sends nothing;
* what was paid is counted: the episode's cost is its calls' cost, which is the ledger's spend,
  never below the provider's own bill, and within the run cap.
"""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass
from pathlib import Path

import pytest

from pipeline.cli import main
from pipeline.sqlview import open_tables
from pipeline.store import RunStore
from recap.row_bounds import MAX_ARGUMENTS_CHARS
from workers.envs.swe.examples import make_fixtures
from workers.gateway.entries import journal_spend
from workers.gateway.ledger import JOURNAL_NAME
from workers.llm.offline.fake_server import FakeServer
from workers.llm.offline.fake_server.faults import DEEP_LEVELS
from workers.llm.pricing import default_prices, usd_to_pico

PRICE = default_prices().get("openai/fake-gpt")  # TEST DOUBLE price: $1/M input, $0.5/M cached, $2/M output
KEY_ENV = "RECAP_FAKE_KEY"
CAP_USD = 2.0
CALLS = 3

SPEC = """run: {name}
output: {out}
run_cap_usd: {cap}
models:
  - model: openai/fake-gpt
    label: hostile
    api_base: {url}
    api_key_env: RECAP_FAKE_KEY
    retries: 1
    params: {{max_tokens: 64}}
methods:
  - method: recap
    profile: paper
environments:
  - benchmark: swe
    tasks: [all]
    options: {{instances_file: "{tasks}", sandbox: local, grading: ours}}
limits: {{llm_calls: {calls}}}
workers: 1
"""


def hostile_sweep(tmp_path: Path, server: FakeServer, name: str = "hostile") -> tuple[Path, Path]:
    """A one-unit coding sweep against ``server`` (its run folder, its sweep file)."""
    fixtures = make_fixtures(tmp_path / "fixtures", ("format",))
    out = tmp_path / name
    spec_file = tmp_path / f"{name}.yaml"
    spec_file.write_text(
        SPEC.format(name=name, out=out, cap=CAP_USD, url=server.base_url, tasks=fixtures.tasks_file, calls=CALLS)
    )
    return out, spec_file


def bill_pico(server: FakeServer) -> int:
    """What the provider billed: every 200 it answered, at its own token counts."""
    return sum(PRICE.cost_pico(c.prompt_tokens, c.cached_tokens, c.completion_tokens) for c in server.log if c.status == 200)


def q(out: Path, sql: str) -> list[tuple]:
    con, _ = open_tables(RunStore(out))
    return con.execute(sql).fetchall()


@dataclass(frozen=True)
class RunAndResume:
    """What ``recap run`` and then ``recap resume`` of a hostile sweep left (the chaos lab reads it too)."""

    run_exit: int
    resume_exit: int
    #: requests the provider answered by the end of the run, and by the end of the resume
    sent: int
    sent_after_resume: int
    #: the episode rows: (end_reason, error, llm_calls, cost_usd)
    episodes: list[tuple]
    #: the tool_calls rows: (index, step_index, name, arguments, valid, error, has a message, exit_code)
    tool_calls: list[tuple]
    #: (status, error_kind) of each llm_calls row, and their cost
    calls: list[tuple]
    calls_cost_usd: float
    spent_pico: int
    reserved_pico: int
    spent_after_resume_pico: int
    bill_pico: int


def run_and_resume(tmp_path: Path, server: FakeServer, name: str = "hostile") -> RunAndResume:
    """``recap run`` of a one-unit hostile sweep, then ``recap resume`` of its folder (in-process,
    on the Ray this process joined)."""
    out, spec_file = hostile_sweep(tmp_path, server, name)
    with contextlib.redirect_stdout(io.StringIO()):
        run_exit = main(["run", str(spec_file), "--progress", "off"])
    sent = len(server.log)
    ledger = journal_spend((out / JOURNAL_NAME).read_bytes())
    episodes = q(out, "select end_reason, error, llm_calls, cost_usd from episodes")
    tool_calls = q(
        out,
        'select "index", step_index, name, arguments, valid, error, message_seq is not null, exit_code '
        'from tool_calls order by "index"',
    )
    calls = q(out, "select status, error_kind from llm_calls order by call_index")
    (calls_cost,) = q(out, "select coalesce(sum(cost_usd), 0) from llm_calls")[0]
    with contextlib.redirect_stdout(io.StringIO()):
        resume_exit = main(["resume", str(out), "--progress", "off"])
    return RunAndResume(
        run_exit=run_exit,
        resume_exit=resume_exit,
        sent=sent,
        sent_after_resume=len(server.log),
        episodes=episodes,
        tool_calls=tool_calls,
        calls=calls,
        calls_cost_usd=calls_cost,
        spent_pico=ledger.spent_pico,
        reserved_pico=ledger.reserved_pico,
        spent_after_resume_pico=journal_spend((out / JOURNAL_NAME).read_bytes()).spent_pico,
        bill_pico=bill_pico(server),
    )


def expected_deep_rows() -> list[tuple]:
    """The tool_calls rows of the deep-arguments sweep: one invalid call per reply, cut to the bound."""
    deep = "[" * DEEP_LEVELS + "]" * DEEP_LEVELS
    kept = deep[:MAX_ARGUMENTS_CHARS] + f" [cut: {len(deep)} characters in all]"
    error = f"arguments nest {DEEP_LEVELS} levels deep (at most 64 are read)"
    return [(i, i, "bash", kept, False, error, True, None) for i in range(CALLS)]


@pytest.mark.slow  # a Ray run with a sandboxed coding episode: about a minute on a small machine
def test_deeply_nested_arguments_are_the_models_invalid_calls_and_resume_pays_nothing(
    ray_address, tmp_path, monkeypatch, fake_server
):
    monkeypatch.setenv(KEY_ENV, "not-a-secret")
    server = fake_server(fault_rates={"deepargs": 1.0})
    r = run_and_resume(tmp_path, server)
    assert r.run_exit == 0 and r.sent == CALLS
    assert {(c.status, c.mode) for c in server.log} == {(200, "deepargs")}
    (episode,) = r.episodes
    assert episode[:3] == ("call_cap", f"{CALLS} LLM calls (cap {CALLS})", CALLS)
    assert r.tool_calls == expected_deep_rows()
    assert r.calls == [("ok", None)] * CALLS
    # what was paid is counted: the episode's cost is its calls', the ledger's, within the cap
    assert episode[3] == pytest.approx(r.calls_cost_usd, abs=1e-12) == pytest.approx(r.spent_pico / 1e12, abs=1e-12)
    assert 0 < r.bill_pico <= r.spent_pico <= usd_to_pico(CAP_USD) and r.reserved_pico == 0
    # a resume has nothing to do: the unit is done, nothing is sent or paid again
    assert r.resume_exit == 0 and r.sent_after_resume == r.sent and r.spent_after_resume_pico == r.spent_pico
