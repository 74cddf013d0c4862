"""The budget ledger's memory stays flat over a long run, and idempotency still holds.

The recorded responses (``call_key`` -> response, fingerprint -> cached response) live in a
temporary SQLite file (workers/gateway/recorded.py), not in the ledger's Python objects: the
ledger's heap must not grow with the calls settled, and a call_key recorded thousands of calls
ago is still answered with its exact response, before and after a restart.
"""

from __future__ import annotations

import gc
import tracemalloc

from workers.gateway.ledger import BudgetLedger
from workers.gateway.recorded import RecordedResults

#: a response about the size of a short chat answer (the journal records it whole)
TEXT = "I pick up the red block and put it on the blue one. " * 12


def _result(i: int) -> dict:
    return {"text": f"{i}: {TEXT}", "usage": {"prompt_tokens": 900 + i % 7, "completion_tokens": 60}, "model": "m"}


def _settle_calls(led: BudgetLedger, start: int, n: int) -> None:
    for i in range(start, start + n):
        answer = led.begin(f"run-1:unit{i // 10}-1:call{i % 10}", "m", 1000, cache_key=f"fp{i}", owner="g")
        assert answer["status"] == "reserved"
        led.settle(answer["rid"], 400, "ok", _result(i), cache_key=f"fp{i}")


def _heap_after(led: BudgetLedger, start: int, n: int) -> int:
    _settle_calls(led, start, n)
    gc.collect()
    return tracemalloc.get_traced_memory()[0]


def test_settled_calls_do_not_grow_the_ledgers_heap(tmp_path):
    led = BudgetLedger(tmp_path, fsync=False)
    _settle_calls(led, 0, 300)  # warm-up: every code path and SQLite's page cache in use
    tracemalloc.start()
    try:
        before = _heap_after(led, 300, 100)
        after = _heap_after(led, 400, 3000)
    finally:
        tracemalloc.stop()
    # a dict of responses grows by ~1.5 KB a call (each response and key twice: results, cache),
    # 4.5 MB here; what is left is allocator noise
    assert after - before < 3000 * 50, f"the ledger's heap grew by {after - before} bytes over 3000 calls"
    assert led.stats()["recorded_results"] == 3400 and led.stats()["cached_results"] == 3400
    led.close()


def test_a_call_key_recorded_long_ago_is_served_before_and_after_a_restart(tmp_path):
    led = BudgetLedger(tmp_path, fsync=False)
    _settle_calls(led, 0, 2000)
    early = led.begin("run-1:unit0-1:call3", "m", 1000, owner="g")
    assert early == {"status": "recorded", "served_from": "ledger", "result": _result(3)}
    assert led.begin("new-key", "m", 1000, cache_key="fp17", owner="g") == {
        "status": "recorded",
        "served_from": "cache",
        "result": _result(17),
    }
    spent = led.spent
    led.close()

    again = BudgetLedger(tmp_path, fsync=False)
    assert again.spent == spent == 2000 * 400
    assert again.begin("run-1:unit0-1:call3", "m", 1000, owner="g") == early
    assert again.begin("run-1:unit199-1:call9", "m", 1000, owner="g")["result"] == _result(1999)
    assert again.begin("run-1:unit200-1:call0", "m", 1000, owner="g")["status"] == "reserved"  # never made
    assert again.stats()["recorded_results"] == 2000
    again.close()


def test_recorded_results_map():
    rec = RecordedResults(cache_kib=64)
    assert "a" not in rec and len(rec) == 0
    rec["a"] = {"text": "x", "n": [1, 2]}
    rec["a"] = {"text": "y"}  # a later ok settlement of the same call replaces the first
    assert "a" in rec and rec["a"] == {"text": "y"} and len(rec) == 1
    try:
        rec["b"]
    except KeyError as exc:
        assert exc.args == ("b",)
    else:
        raise AssertionError("a missing key must raise KeyError")
    rec["b"] = {"text": "z"}
    assert list(rec) == ["a", "b"]
    rec.close()
    assert len(rec) == 2  # the ledger's stats() reads it after close (the run's last stats)
