"""One model config, one key: a sweep model entry maps onto the gateway's deployment through one
table, the deployment is named after the model's name in the sweep, and caps, reservations,
journal entries and spend are kept by that name - so two entries on one model string have their
own caps and spend. Journals written before (keyed by model string) still resume."""

from __future__ import annotations

import json

import pytest

from pipeline.errors import RunFolderError
from pipeline.gateway_backend import deployment_config, model_caps, provider_models
from pipeline.resume import attempt_spend, check_journal, journal_episode_ids
from pipeline.spec import DEPLOYMENT_FIELDS, SPEC_ONLY_FIELDS, ModelSpec, parse_spec
from pipeline.store import RunStore
from workers.gateway.entries import AttemptSpend, LedgerKeyError
from workers.gateway.ledger import JOURNAL_NAME, BudgetLedger
from workers.llm.providers import DeploymentConfig

PICO = 10**12

TWO_ON_ONE = """run: two
output: {out}
models:
  - model: offline/expert
    label: expert-a
    options: {{seed: 1}}
    cap_usd: 0.5
  - model: offline/expert
    label: expert-b
    options: {{seed: 2}}
    cap_usd: 2.0
  - model: offline/random
methods: [{{method: react}}]
environments: [{{benchmark: blocksworld, tasks: ["3"]}}]
"""


def two_on_one(tmp_path):
    return parse_spec(TWO_ON_ONE.format(out=tmp_path / "run"), "sweep.yaml")


# -- one config -----------------------------------------------------------------------------------
def test_every_model_entry_field_maps_to_the_deployment_or_is_the_spec_own():
    assert set(ModelSpec.model_fields) == set(DEPLOYMENT_FIELDS) | SPEC_ONLY_FIELDS
    assert not set(DEPLOYMENT_FIELDS) & SPEC_ONLY_FIELDS
    assert set(DEPLOYMENT_FIELDS.values()) <= set(DeploymentConfig.model_fields)


def test_a_model_entry_becomes_its_deployment_field_by_field():
    m = ModelSpec(
        model="openai/gpt-4o",
        label="fast",
        params={"temperature": 0.2},
        rpm=10,
        tpm=1000,
        concurrency=3,
        window_s=30,
        retries=4,
        timeout_s=50,
        max_usage_rejections=2,
        api_base="http://127.0.0.1:9/v1",
        api_key_env="MY_KEY",
        prices={"input": 1, "output": 2},
        cap_usd=5,
    )
    cfg = deployment_config(m, "models[0]")
    got = {f: getattr(cfg, f) for f in DEPLOYMENT_FIELDS.values() if f != "price"}
    assert got == {
        "model": "openai/gpt-4o",
        "name": "fast",
        "params": {"temperature": 0.2},
        "offline_options": {},
        "rpm": 10,
        "tpm": 1000,
        "max_concurrency": 3,
        "window_s": 30.0,
        "max_attempts": 5,
        "attempt_timeout_s": 50.0,
        "max_usage_rejections": 2,
        "api_base": "http://127.0.0.1:9/v1",
        "api_key_env": "MY_KEY",
    }
    assert (cfg.price.input, cfg.price.output, cfg.price.cached_input) == (1.0, 2.0, None)
    assert cfg.deployment_name == m.name == "fast"
    # left out: the gateway's defaults; unlabelled: the deployment is named after the model string
    bare = deployment_config(ModelSpec(model="openai/gpt-4o", api_base="http://127.0.0.1:9/v1"), "models[1]")
    defaults = DeploymentConfig(model="x")
    assert (
        bare.name,
        bare.deployment_name,
        bare.max_attempts,
        bare.max_concurrency,
        bare.attempt_timeout_s,
        bare.window_s,
        bare.price,
    ) == (
        "openai/gpt-4o",
        "openai/gpt-4o",
        defaults.max_attempts,
        defaults.max_concurrency,
        defaults.attempt_timeout_s,
        defaults.window_s,
        None,
    )


def test_caps_and_the_ledger_names_are_the_sweep_names(tmp_path):
    spec = two_on_one(tmp_path)
    assert model_caps(spec) == {"expert-a": 0.5, "expert-b": 2.0}  # two caps on one model string
    assert provider_models(spec) == {
        "expert-a": "offline/expert",
        "expert-b": "offline/expert",
        "offline/random": "offline/random",
    }
    assert [deployment_config(m, "m").deployment_name for m in spec.models] == ["expert-a", "expert-b", "offline/random"]


# -- one key: the ledger ----------------------------------------------------------------------------
def test_two_names_on_one_model_string_have_their_own_caps_and_spend(tmp_path):
    led = BudgetLedger(
        tmp_path,
        model_caps_usd={"expert-a": 0.5, "expert-b": 2.0},
        fsync=False,
        provider_models={"expert-a": "offline/expert", "expert-b": "offline/expert"},
    )
    a = led.reserve("ea-1#0", "expert-a", 4 * PICO // 10)
    led.settle(a["rid"], 3 * PICO // 10, "ok")
    refused = led.reserve("ea-1#1", "expert-a", 3 * PICO // 10)
    assert refused["refusal"] == {
        "scope": "model",
        "model": "expert-a",
        "cap_pico": PICO // 2,
        "committed_pico": 3 * PICO // 10,
        "worst_pico": 3 * PICO // 10,
    }
    b = led.reserve("eb-1#0", "expert-b", 15 * PICO // 10)  # expert-a's cap does not stop expert-b
    assert b["status"] == "reserved"
    led.settle(b["rid"], PICO, "ok")
    assert led.stats()["by_model_spent_usd"] == {"expert-a": 0.3, "expert-b": 1.0}
    led.close()
    lines = [json.loads(x) for x in (tmp_path / JOURNAL_NAME).read_text().splitlines()]
    assert [(e["op"], e["name"], "model" in e) for e in lines] == [
        ("reserve", "expert-a", False),
        ("settle", "expert-a", False),
        ("reserve", "expert-b", False),
        ("settle", "expert-b", False),
    ]


def _legacy_journal(path, model="offline/expert"):
    """A journal as the ledger wrote it before spend was kept by name (entries keyed by model)."""
    lines = [
        {"op": "reserve", "rid": 1, "key": "u1-1#0", "model": model, "pico": 500, "owner": "g:1", "t": 0},
        {
            "op": "settle",
            "rid": 1,
            "key": "u1-1#0",
            "model": model,
            "pico": 300,
            "status": "ok",
            "result": {"text": "x", "prompt_tokens": 20, "cached_prompt_tokens": 4, "completion_tokens": 5},
            "t": 0,
        },
        {"op": "reserve", "rid": 2, "key": "u2-1#0", "model": model, "pico": 700, "owner": "g:1", "t": 0},
        {"op": "reserve", "rid": 3, "key": "u3-1#0", "model": "openai/gone", "pico": 50, "owner": "h:1", "t": 0},
        {"op": "settle", "rid": 3, "key": "u3-1#0", "model": "openai/gone", "pico": 40, "status": "ok", "t": 0},
    ]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("".join(json.dumps(e) + "\n" for e in lines))


def test_an_old_journal_keyed_by_model_string_resumes_under_the_one_name_serving_it(tmp_path):
    _legacy_journal(tmp_path / JOURNAL_NAME)
    led = BudgetLedger(
        tmp_path,
        model_caps_usd={"expert-a": 1.2 * 10**-9},
        fsync=False,
        provider_models={"expert-a": "offline/expert", "gpt": "openai/gpt-4o"},
    )
    # the open reservation (rid 2) is charged at its worst case, under expert-a
    assert (led.spent, dict(led.spent_by_model)) == (300 + 700 + 40, {"expert-a": 1000, "openai/gone": 40})
    assert led.reserve("u4-1#0", "expert-a", 300)["refusal"]["scope"] == "model"  # 1000 + 300 > 1200
    assert led.reserve("u4-1#0", "gpt", 300)["status"] == "reserved"
    led.close()
    again = BudgetLedger(tmp_path, fsync=False, provider_models={"expert-a": "offline/expert", "gpt": "openai/gpt-4o"})
    # gpt's open reservation, written by name, is charged at its worst case under that name
    assert dict(again.spent_by_model) == {"expert-a": 1000, "openai/gone": 40, "gpt": 300}
    again.close()
    last = json.loads((tmp_path / JOURNAL_NAME).read_text().splitlines()[-1])
    assert (last["op"], last["name"], last["status"], last["pico"]) == ("settle", "gpt", "orphaned", 300)


AMBIGUOUS = (
    "{where} was written before spend was kept per model name: its entries name model 'offline/expert', "
    "which 'expert-a', 'expert-b' of this sweep share, so their spend cannot be split between them; "
    "resume with one sweep entry on that model, or use a new output folder"
)


def test_an_old_journal_whose_model_string_two_names_share_is_refused(tmp_path):
    spec = two_on_one(tmp_path)
    out = tmp_path / "run"
    _legacy_journal(out / JOURNAL_NAME)
    with pytest.raises(LedgerKeyError) as err:
        BudgetLedger(out, fsync=False, provider_models=provider_models(spec))
    assert str(err.value) == AMBIGUOUS.format(where=out / JOURNAL_NAME)
    BudgetLedger(out, fsync=False).close()  # the refused ledger let go of the journal
    with pytest.raises(RunFolderError) as err2:
        check_journal(RunStore(out), provider_models(spec))
    assert str(err2.value) == AMBIGUOUS.format(where=f"ledger journal {out}/{JOURNAL_NAME}")
    check_journal(RunStore(out), {"expert-a": "offline/expert"})  # one name serves it: fine


def test_resume_reads_episode_ids_and_attempt_spend_through_the_journal_format(tmp_path):
    _legacy_journal(tmp_path / JOURNAL_NAME)
    store = RunStore(tmp_path)
    assert journal_episode_ids(store) == {"u1-1", "u2-1", "u3-1"}
    assert attempt_spend(store, "u1-1") == AttemptSpend(1, 20, 4, 5, 300 / PICO)
    assert attempt_spend(store, "u2-1") == AttemptSpend()  # reserved, never settled
    assert attempt_spend(store, "nope") == AttemptSpend()


# -- end to end: a sweep on Ray through the gateway ------------------------------------------------
E2E = """run: {name}
output: {out}
models:
  - model: offline/expert
    label: expert-a
    options: {{seed: 1}}
    cap_usd: {cap}
  - model: offline/expert
    label: expert-b
    options: {{seed: 2}}
    cap_usd: 1.0
methods: [{{method: react}}]
environments: [{{benchmark: blocksworld, tasks: ["3"]}}]
workers: 2
order: plan
"""


def test_a_sweep_keeps_spend_and_caps_apart_for_two_names_on_one_model_string(ray_address, tmp_path):
    from pipeline.driver import Driver, prepare
    from pipeline.gateway_backend import make_backend
    from pipeline.sqlview import open_tables

    out = tmp_path / "e2e"
    cap = 0.012  # about two thirds of what the three episodes of expert-a need
    text = E2E.format(name="e2e", out=out, cap=cap)
    spec = parse_spec(text, "sweep.yaml")
    summary = Driver(prepare(spec, text), make_backend(spec), progress="off").run()
    assert (summary.total, summary.stopped) == (6, "expert-a capped")
    con, bad = open_tables(RunStore(out))
    assert bad == []
    q = lambda sql: con.execute(sql).fetchall()  # noqa: E731
    # the cap on expert-a did not stop expert-b, which shares its model string
    assert q("select end_reason, count(*) from episodes where model = 'expert-b' group by 1") == [("success", 3)]
    a_rows = q("select end_reason from episodes where model = 'expert-a'")
    assert a_rows.count(("success",)) < 3 and not summary.all_done
    # every call carries both names; each name's spend is its own
    assert q("select distinct model, model_name, deployment from llm_calls order by 2") == [
        ("offline/expert", "expert-a", "expert-a"),
        ("offline/expert", "expert-b", "expert-b"),
    ]
    spent = dict(q("select model_name, sum(cost_usd) from llm_calls group by 1"))
    assert 0 < spent["expert-a"] <= cap and spent["expert-b"] > cap
    # episodes and their calls agree on the model's name and on what each attempt paid
    assert q("""select count(*) from episodes e join llm_calls c using (episode_id)
                where c.model_name <> e.model or c.model <> e.provider_model""") == [(0,)]
    assert q("""select count(*) from episodes e where abs(e.cost_usd -
                (select coalesce(sum(c.cost_usd), 0) from llm_calls c where c.episode_id = e.episode_id)) > 1e-9""") == [(0,)]
    assert q("select detail->>'model' from events where kind = 'model_cap_reached'") == [("expert-a",)]
    # the ledger journal keeps the same split, by name
    journal = [json.loads(x) for x in (out / JOURNAL_NAME).read_text().splitlines()]
    assert {e["name"] for e in journal} == {"expert-a", "expert-b"} and not any("model" in e for e in journal)
    by_name = {n: sum(e["pico"] for e in journal if e["op"] == "settle" and e["name"] == n) / PICO for n in spent}
    assert by_name == pytest.approx(spent, abs=1e-9)

    # the same journal as recap wrote it before (keyed by model string): the two labels' spend
    # cannot be told apart any more, so a resume is refused, in one line, before anything starts
    legacy = [{("model" if k == "name" else k): ("offline/expert" if k == "name" else v) for k, v in e.items()} for e in journal]
    (out / JOURNAL_NAME).write_text("".join(json.dumps(e) + "\n" for e in legacy))
    with pytest.raises(RunFolderError) as err:
        prepare(spec, text)
    assert str(err.value) == AMBIGUOUS.format(where=f"ledger journal {out}/{JOURNAL_NAME}")
