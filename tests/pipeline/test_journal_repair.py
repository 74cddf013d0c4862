"""A torn or corrupt line in the gateway's ledger journal (no Ray): ``recap status`` names it in
one line (file and line), the repair cuts a torn last line keeping a backup and refuses a
corrupt line in the middle, a resume refuses the corrupt journal in one line before it starts
anything, and the ledger's own replay copes with any torn tail (garbage, zero bytes)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pipeline.cli import main
from pipeline.driver import prepare
from pipeline.errors import RunFolderError
from pipeline.resume import journal_issue, load_state, repair_run, scan_journal
from pipeline.spec import parse_spec
from pipeline.store import RunStore
from pipeline.units import expand
from workers.gateway.journal import Journal, JournalError
from workers.gateway.ledger import JOURNAL_NAME, BudgetLedger

SPEC = """run: torn
output: {out}
models: [{{model: offline/expert}}]
methods: [{{method: react}}]
environments: [{{benchmark: blocksworld, tasks: ["3"]}}]
"""

ENTRIES = [
    {"op": "reserve", "rid": 1, "key": "u-1#0", "model": "m", "pico": 50, "owner": "g", "t": 0},
    {"op": "settle", "rid": 1, "key": "u-1#0", "model": "m", "pico": 30, "status": "ok", "t": 0},
    {"op": "reserve", "rid": 2, "key": "u-1#1", "model": "m", "pico": 50, "owner": "g", "t": 0},
    {"op": "settle", "rid": 2, "key": "u-1#1", "model": "m", "pico": 20, "status": "ok", "t": 0},
]
GOOD = b"".join(json.dumps(e).encode() + b"\n" for e in ENTRIES)

TORN_TAILS = {
    "prefix": b'{"op": "reserve", "rid": 3, "ke',
    "prefix+newline": b'{"op": "reserve", "rid": 3, "ke\n',
    "zero bytes": b"\x00" * 37,
    "garbage": b"\xff\xfe\x81garbage\x00",
    "not an object": b"17\n",
}


def _run_folder(tmp_path: Path, journal: bytes) -> Path:
    out = tmp_path / "run"
    text = SPEC.format(out=out)
    store = RunStore(out)
    store.create_identity("torn")
    store.write_text("spec.yaml", text)
    store.write_text("plan.json", expand(parse_spec(text)).to_json())
    (out / "gateway").mkdir()
    (out / JOURNAL_NAME).write_bytes(journal)
    return out


@pytest.mark.parametrize("tail", list(TORN_TAILS), ids=list(TORN_TAILS))
def test_a_torn_last_line_is_named_by_status_and_cut_by_repair_with_a_backup(tmp_path, capsys, tail):
    out = _run_folder(tmp_path, GOOD + TORN_TAILS[tail])
    journal = out / JOURNAL_NAME
    assert load_state(RunStore(out)).last_attempt == {"u": 1}  # resume's own read copes too
    assert main(["status", str(out)]) == 0
    lines = [ln for ln in capsys.readouterr().out.splitlines() if "ledger journal" in ln]
    assert lines == [
        f"ledger journal {journal}: line 5 of 5 is torn (a crash mid-write); the next resume drops it, "
        f"keeping a backup (or now: recap resume {out} --repair)"
    ]

    said = repair_run(RunStore(out))
    assert said.startswith(f"repaired {journal}: cut the torn last line 5 (")
    assert journal.read_bytes() == GOOD
    (backup,) = journal.parent.glob("ledger.jsonl.bak-*")
    assert backup.read_bytes() == GOOD + TORN_TAILS[tail] and str(backup) in said
    assert journal_issue(RunStore(out)) is None
    assert repair_run(RunStore(out)) == f"nothing to repair in {out}: the ledger journal is intact"
    assert BudgetLedger(out).spent == 50


def test_a_corrupt_line_in_the_middle_is_refused_by_repair_status_and_resume(tmp_path, capsys):
    lines = GOOD.splitlines(keepends=True)
    damaged = b"".join(lines[:2]) + b'{"op": "reserve", "rid": 2, "key": "u-1#1", "mo\n' + lines[3]
    out = _run_folder(tmp_path, damaged)
    journal = out / JOURNAL_NAME
    expected = (
        f"ledger journal {journal}: line 3 of 4 is corrupt and not the last line; the run's spend cannot be "
        f"restored from it - restore the file from a backup"
    )
    assert main(["status", str(out)]) == 0
    assert [ln for ln in capsys.readouterr().out.splitlines() if "ledger journal" in ln] == [
        expected + " (recap resume --repair only cuts a torn last line)"
    ]

    with pytest.raises(RunFolderError) as err:
        repair_run(RunStore(out))
    assert str(err.value) == expected + " - --repair only cuts a torn last line, so it changed nothing"
    assert journal.read_bytes() == damaged and not list(journal.parent.glob("*.bak-*"))

    # a resume stops before anything starts: one line, exit 2, nothing written
    capsys.readouterr()
    assert main(["resume", str(out), "--progress", "off"]) == 2
    err_lines = capsys.readouterr().err.strip().splitlines()
    assert err_lines == [f"recap: error: {expected} (recap resume --repair only cuts a torn last line)"]
    assert journal.read_bytes() == damaged
    with pytest.raises(RunFolderError):
        prepare(parse_spec(SPEC.format(out=out)), SPEC.format(out=out))
    with pytest.raises(JournalError, match=r"line 3 is corrupt and not the last one"):
        list(Journal(journal).replay())


@pytest.mark.parametrize("tail", list(TORN_TAILS), ids=list(TORN_TAILS))
def test_the_ledger_replay_cuts_any_torn_tail_and_keeps_its_bytes(tmp_path, tail):
    out = _run_folder(tmp_path, GOOD + TORN_TAILS[tail])
    led = BudgetLedger(out)
    assert led.spent == 50
    led.close()
    journal = out / JOURNAL_NAME
    assert journal.read_bytes() == GOOD
    kept = [p.read_bytes() for p in journal.parent.glob("ledger.jsonl.torn-*")]
    assert kept == ([] if tail == "zero bytes" else [TORN_TAILS[tail]])  # zero bytes say nothing: not kept


def test_a_resume_is_not_refused_for_a_torn_last_line(tmp_path):
    out = _run_folder(tmp_path, GOOD + TORN_TAILS["prefix"])
    prepared = prepare(parse_spec(SPEC.format(out=out)), SPEC.format(out=out))
    assert prepared.identity is not None


def test_repair_refuses_while_a_live_ledger_holds_the_journal(tmp_path):
    out = _run_folder(tmp_path, GOOD)
    led = BudgetLedger(out)
    with open(out / JOURNAL_NAME, "ab") as fh:
        fh.write(b'{"op": "res')
    with pytest.raises(RunFolderError, match="held by a live ledger"):
        repair_run(RunStore(out))
    led.close()


def test_scan_journal_line_numbers():
    assert scan_journal(GOOD) is None
    assert scan_journal(b"") is None
    assert scan_journal(GOOD + b"\n\n") is None
    issue = scan_journal(GOOD + b"{")
    assert (issue.line, issue.lines, issue.torn, issue.good_end) == (5, 5, True, len(GOOD))
    issue = scan_journal(b"{\n" + GOOD)
    assert (issue.line, issue.lines, issue.torn) == (1, 5, False)
