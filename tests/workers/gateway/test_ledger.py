"""The budget ledger: caps, exact settlement, restore from the journal, single writer."""

from __future__ import annotations

import json

import pytest

from workers.gateway.journal import JournalError
from workers.gateway.ledger import JOURNAL_NAME, BudgetLedger

USD = 10**12  # pico-dollars per dollar


def test_reservations_are_refused_past_run_and_model_caps(tmp_path):
    led = BudgetLedger(tmp_path, run_cap_usd=1.0, model_caps_usd={"m-a": 0.5})
    r1 = led.begin("ep#0", "m-a", USD * 4 // 10, owner="g")
    assert r1["status"] == "reserved"
    refused = led.begin("ep#1", "m-a", USD * 2 // 10, owner="g")  # 0.4 + 0.2 > 0.5 (model cap)
    assert refused["status"] == "refused" and refused["message"].startswith("m-a budget:")
    led.settle(r1["rid"], USD // 10, "ok", {"text": "hi"})
    assert led.begin("ep#1", "m-a", USD * 2 // 10, owner="g")["status"] == "reserved"
    r3 = led.begin("ep#2", "m-b", USD * 71 // 100, owner="g")  # 0.1 + 0.2 + 0.71 > 1.0
    assert r3["status"] == "refused" and r3["message"].startswith("run budget:")
    stats = led.stats()
    assert stats["spent_usd"] == 0.1 and stats["committed_usd"] == 0.3 and stats["refusals"] == 2
    led.close()


def test_exactly_at_the_cap_is_allowed(tmp_path):
    led = BudgetLedger(tmp_path, run_cap_usd=0.3)
    assert led.begin("a", "m", USD // 10)["status"] == "reserved"
    assert led.begin("b", "m", USD // 5)["status"] == "reserved"  # 0.1 + 0.2 == 0.3
    assert led.begin("c", "m", 1)["status"] == "refused"
    led.close()


def test_unpriced_model_is_refused_only_under_a_cap(tmp_path):
    led = BudgetLedger(tmp_path / "a")
    assert led.begin("k", "m", None)["status"] == "reserved"
    led.close()
    capped = BudgetLedger(tmp_path / "b", run_cap_usd=5)
    answer = capped.begin("k", "m", None)
    assert answer["status"] == "refused" and "no price for model m" in answer["message"]
    capped.close()


def test_restart_restores_spend_results_and_charges_open_reservations(tmp_path):
    led = BudgetLedger(tmp_path, run_cap_usd=1.0)
    a = led.begin("ep#0", "m", 300, cache_key="c0")
    led.settle(a["rid"], 123, "ok", {"text": "first"}, cache_key="c0")
    b = led.begin("ep#1", "m", 500)
    led.charge_worst(b["rid"])  # a timed-out attempt
    c = led.reserve("ep#1", "m", 500)
    led.settle(c["rid"], 77, "ok", {"text": "second"})
    led.begin("ep#2", "m", 999)  # in flight when the process dies
    led._journal.close()  # the process dies: nothing else is written

    again = BudgetLedger(tmp_path, run_cap_usd=1.0)
    assert again.spent == 123 + 500 + 77 + 999  # the open reservation is charged at worst case
    assert again.reserved == 0 and again.restored_orphans == 1
    assert again.begin("ep#0", "m", 300) == {"status": "recorded", "served_from": "ledger", "result": {"text": "first"}}
    assert again.begin("ep#9", "m", 300, cache_key="c0")["served_from"] == "cache"
    again.close()
    third = BudgetLedger(tmp_path)  # the orphan settlement itself was journaled
    assert third.spent == 123 + 500 + 77 + 999 and third.restored_orphans == 0
    third.close()


def test_torn_last_line_is_dropped_and_cut(tmp_path):
    led = BudgetLedger(tmp_path)
    r = led.begin("ep#0", "m", 10)
    led.settle(r["rid"], 7, "ok", {"text": "x"})
    led.close()
    path = tmp_path / JOURNAL_NAME
    good = path.read_bytes()
    path.write_bytes(good + b'{"op":"reserve","rid":3,"ke')
    again = BudgetLedger(tmp_path)
    assert again.spent == 7
    again.close()
    assert path.read_bytes() == good
    assert [json.loads(x)["op"] for x in good.splitlines()] == ["reserve", "settle"]


def test_one_live_ledger_per_run_folder(tmp_path):
    led = BudgetLedger(tmp_path)
    with pytest.raises(JournalError, match="held by another live ledger"):
        BudgetLedger(tmp_path, lock_timeout_s=0.1)
    led.close()
    BudgetLedger(tmp_path).close()


def test_a_restarted_gateway_charges_only_its_dead_predecessors_reservations(tmp_path):
    led = BudgetLedger(tmp_path)
    led.begin("a", "m", 100, owner="dep@http://h:1/v1:dead0001")
    led.begin("b", "m", 200, owner="dep@http://h:1/v1:live0002")
    led.begin("c", "m", 400, owner="other:dead0003")
    assert led.adopt_orphans("dep@http://h:1/v1", keep_owner="dep@http://h:1/v1:live0002") == 1
    assert (led.spent, led.reserved) == (100, 600)
    led.close()
