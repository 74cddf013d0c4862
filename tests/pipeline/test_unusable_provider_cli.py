"""A provider that answers HTTP 200 with nothing usable, or lies about its usage, through the real
CLI on a local Ray (issue 24, classes 1 and 5):

* a provider that only answers unreadable 200s (a body that is not JSON, an HTML page, no
  choices) under a $0.005 run cap: ``recap run`` then two ``recap resume``: the provider's own
  bill (what the fake server was asked, at the model's price) never passes the cap - before,
  each reply was charged $0 and every resume paid again;
* the stop line, ``recap status`` and the ledger journal print one spend figure on that run,
  whose calls were all charged at their worst case;
* a 200 without a usable choice (``choices: []``, null content) is the provider's failure: the
  unit ends ``infra_error`` (exit 4), which ``recap resume`` retries - not a JSON failure of the
  model that no resume retries;
* two models in one sweep, one whose usage is always impossible: its units stop after
  ``max_usage_rejections`` replies with one line and a ``model_stopped`` event, the honest one
  finishes all its units.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from pipeline.cli import main
from pipeline.driver import EXIT_INFRA, EXIT_WORK_REMAINS
from pipeline.sqlview import open_tables
from pipeline.store import RunStore
from workers.gateway.entries import journal_spend
from workers.gateway.ledger import JOURNAL_NAME
from workers.llm.offline.fake_server import FakeServer
from workers.llm.pricing import default_prices, usd_to_pico

PRICE = default_prices().get("openai/fake-gpt")  # TEST DOUBLE price: $1/M input, $0.5/M cached, $2/M output
KEY_ENV = "RECAP_FAKE_KEY"

MODEL = """  - model: openai/fake-gpt
    label: {label}
    api_base: {url}
    api_key_env: RECAP_FAKE_KEY
    retries: 1
    params: {{max_tokens: {max_tokens}}}
"""
SWEEP = """run: {name}
output: {out}
{cap}models:
{models}methods: [{{method: react}}]
environments: [{{benchmark: blocksworld, instances: [{instances}]}}]
limits: {{llm_calls: 4}}
workers: 2
"""


def _sweep(tmp_path: Path, name: str, models: str, units: int, cap: str = "") -> tuple[Path, Path]:
    out = tmp_path / name
    instances = ", ".join(f"blocksworld/{3 + i % 2}@{1 + i // 2}" for i in range(units))
    spec_file = tmp_path / f"{name}.yaml"
    spec_file.write_text(SWEEP.format(name=name, out=out, cap=cap, models=models, instances=instances))
    return out, spec_file


def q(out: Path, sql: str):
    con, _ = open_tables(RunStore(out))
    return con.execute(sql).fetchall()


def bill_pico(server: FakeServer) -> int:
    """What the provider billed: every 200 it answered, at its own token counts."""
    return sum(PRICE.cost_pico(c.prompt_tokens, c.cached_tokens, c.completion_tokens) for c in server.log if c.status == 200)


def test_unreadable_200s_are_charged_so_run_and_resumes_never_pass_the_cap(
    ray_address, tmp_path, capsys, monkeypatch, fake_server
):
    monkeypatch.setenv(KEY_ENV, "not-a-secret")
    # every reply is a 200 nobody can read: not JSON (1/3), else an HTML page (1/2), else no choices
    server = fake_server(fault_rates={"notjson": 1 / 3, "html": 0.5, "nochoices": 1.0}, seed=3)
    cap = 0.005
    out, spec_file = _sweep(
        tmp_path, "unreadable", MODEL.format(label="flaky", url=server.base_url, max_tokens=32), 4, cap=f"run_cap_usd: {cap}\n"
    )
    said = []
    assert main(["run", str(spec_file), "--progress", "off"]) == EXIT_WORK_REMAINS
    said.append(capsys.readouterr().out)
    for _ in range(2):
        assert main(["resume", str(out), "--progress", "off"]) == EXIT_WORK_REMAINS
        said.append(capsys.readouterr().out)

    assert len(server.log) >= 1, said
    assert {c.mode for c in server.log} <= {"notjson", "html", "nochoices"} and {c.status for c in server.log} == {200}
    ledger = journal_spend((out / JOURNAL_NAME).read_bytes())
    # the provider's bill and the ledger both within the cap, the ledger never below the bill
    assert 0 < bill_pico(server) <= ledger.spent_pico <= usd_to_pico(cap) and ledger.reserved_pico == 0
    settles = [json.loads(line) for line in (out / JOURNAL_NAME).read_text().splitlines() if '"settle"' in line]
    assert {e["status"] for e in settles} == {"charged"} and len(settles) == len(server.log)
    # each call row carries what its attempts were charged (a retry refused by the cap fails the
    # call as ``budget``, with the charge of the attempt before it): none of them reads $0
    assert q(out, "select count(*) from llm_calls where cost_usd > 0")[0][0] >= 1
    assert q(out, "select sum(cost_usd) from llm_calls")[0][0] == pytest.approx(ledger.spent_usd, abs=1e-12)
    # a unit ends infra_error (the provider failed, a resume retries it) or budget_exhausted, never as the model's fault
    assert {r for (r,) in q(out, "select distinct end_reason from episodes")} <= {"infra_error", "budget_exhausted"}

    # class 5: one figure - the stop line of every session, status and the journal agree
    spent = f"${ledger.spent_usd:.4f}"
    for text in said:
        assert f"stopped: run cap $0.005 reached (spent {spent}); " in text, text
    # (the sessions after the first: the spend the earlier ones left, nothing more)
    assert main(["status", str(out)]) == 0
    status = capsys.readouterr().out
    assert re.search(rf"; spend \{spent}\n", status), status
    assert len(server.log) == len(settles)  # the resumes sent nothing the journal does not hold

    # status reads the journal, not the llm_calls rows: a call cut by a kill has no row, yet its
    # reservation is open (shown beside the spend) and, once charged as an orphan, spent
    pico = 1_234_000_000
    with open(out / JOURNAL_NAME, "a") as fh:
        fh.write(json.dumps({"op": "reserve", "rid": 999, "key": "x#0", "name": "flaky", "pico": pico, "owner": "dead:1"}) + "\n")
    assert main(["status", str(out)]) == 0
    assert f"; spend {spent} (+ $0.0012 reserved by calls in flight)\n" in capsys.readouterr().out
    with open(out / JOURNAL_NAME, "a") as fh:
        fh.write(
            json.dumps({"op": "settle", "rid": 999, "key": "x#0", "name": "flaky", "pico": pico, "status": "orphaned"}) + "\n"
        )
    assert main(["status", str(out)]) == 0
    assert f"; spend ${ledger.spent_usd + pico / 1e12:.4f}\n" in capsys.readouterr().out


def test_a_lying_provider_is_stopped_after_bounded_replies_and_the_honest_model_finishes(
    ray_address, tmp_path, capsys, monkeypatch, fake_server
):
    monkeypatch.setenv(KEY_ENV, "not-a-secret")
    liar = fake_server(fault_rates={"negusage": 1.0})
    honest = fake_server()
    # (output bounds that differ, so that the two models' units are not identical)
    models = MODEL.format(label="liar", url=liar.base_url, max_tokens=31) + MODEL.format(
        label="honest", url=honest.base_url, max_tokens=32
    )
    out, spec_file = _sweep(tmp_path, "liar", models, 4)
    assert main(["run", str(spec_file), "--progress", "off"]) == EXIT_WORK_REMAINS
    said = capsys.readouterr().out
    why = (
        "liar stopped: liar: provider usage rejected as impossible in 3 replies "
        "(each charged at its worst case); no more calls to it this session"
    )
    assert f"stopped: {why} (spent $" in said, said
    # the liar answered only its bounded replies (at most one more per call already in flight)
    assert 3 <= len(liar.log) <= 4 and {c.mode for c in liar.log} == {"negusage"}
    assert q(out, "select count(*) from events where kind = 'usage_rejected'") == [(len(liar.log),)]
    assert q(out, "select detail->>'model', detail->>'reason' from events where kind = 'model_stopped'") == [("liar", why)]
    done = q(
        out,
        "select model, count(*) from episodes where end_reason not in ('budget_exhausted', 'infra_error') group by model order by model",
    )
    assert ("honest", 4) in done  # the honest model finished every unit
    assert q(out, "select count(*) from episodes where model = 'honest' and end_reason = 'budget_exhausted'") == [(0,)]


def test_a_200_without_a_usable_choice_ends_the_unit_infra_error_and_resume_retries_it(
    ray_address, tmp_path, capsys, monkeypatch, fake_server
):
    monkeypatch.setenv(KEY_ENV, "not-a-secret")
    server = fake_server(fault_rates={"nullcontent": 0.5, "nochoices": 1.0})
    out, spec_file = _sweep(tmp_path, "nochoices", MODEL.format(label="empty", url=server.base_url, max_tokens=32), 1)
    assert main(["run", str(spec_file), "--progress", "off"]) == EXIT_INFRA
    assert "1 unit ended in an infrastructure failure (server_error 1)" in capsys.readouterr().out
    assert main(["resume", str(out), "--progress", "off"]) == EXIT_INFRA
    rows = q(out, "select attempt, end_reason, split_part(error, ':', 1) from episodes order by attempt")
    assert rows == [(1, "infra_error", "server_error"), (2, "infra_error", "server_error")]
    # each unit attempt made one call of 2 attempts (retries: 1), each charged at its reservation
    assert len(server.log) == 4 and {c.mode for c in server.log} <= {"nullcontent", "nochoices"}
    assert q(out, "select count(*), min(retries), min(cost_usd) > 0 from llm_calls") == [(2, 1, True)]
    ledger = journal_spend((out / JOURNAL_NAME).read_bytes())
    assert ledger.spent_pico >= bill_pico(server) > 0
