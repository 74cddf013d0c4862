"""The closed vocabularies (schemas.kinds): every value the code writes is in them, and a record
with a value outside them is refused before it reaches a table."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from schemas import kinds
from schemas.records import CallRecord, EpisodeRecord, EventRecord, NodeRecord
from schemas.tables import VocabularyError, arrow_schema, check_vocabulary, vocabularies

REPO = Path(__file__).resolve().parents[2]


def _string_args(call_names: set[str], position: int, roots: tuple[str, ...]) -> set[tuple[str, str]]:
    """(file, string) for each call ``name(...)`` in ``roots`` whose argument at ``position`` is a
    string literal."""
    found = set()
    for root in roots:
        for path in (REPO / root).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if not isinstance(node, ast.Call):
                    continue
                fn = node.func
                name = fn.attr if isinstance(fn, ast.Attribute) else getattr(fn, "id", None)
                if name == "add" and not (isinstance(fn, ast.Attribute) and ast.unparse(fn.value).endswith("events")):
                    continue  # only the event buffer's add()
                if name in call_names and len(node.args) > position:
                    arg = node.args[position]
                    if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
                        found.add((str(path.relative_to(REPO)), arg.value))
    return found


def test_every_end_reason_the_agents_raise_is_in_the_vocabulary():
    raised = _string_args({"EpisodeEnd"}, 0, ("recap", "workers"))
    assert {r for _, r in raised} >= {"success", "step_cap", "agent_done", "llm_error"}  # the scan sees them
    assert {(f, r) for f, r in raised if r not in kinds.END_REASONS} == set()


def test_every_event_kind_written_is_in_the_vocabulary():
    written = _string_args({"_event", "add", "add_event", "_failed_attempt", "_attempt_event"}, 0, ("pipeline", "workers"))
    written |= _string_args({"_failed_attempt"}, 1, ("pipeline",))
    events = {(f, k) for f, k in written if re.fullmatch(r"[a-z_]+", k)}
    assert {k for _, k in events} >= {"unit_failed", "run_cap_reached", "sink_lost", "retry", "worker_lost"}
    assert {(f, k) for f, k in events if k not in kinds.EVENT_KINDS} == set()


def test_every_llm_error_kind_the_gateway_classifies_is_in_the_vocabulary():
    text = (REPO / "workers/llm/errors.py").read_text()
    assigned = set(re.findall(r'kind = "([a-z_]+)"', text)) | set(re.findall(r'or "([a-z_]+)"', text))
    assert assigned >= {"rate_limit", "timeout", "auth"}
    assert assigned - set(kinds.LLM_ERROR_KINDS) == set()


def test_the_runtime_tuples_are_the_vocabularies():
    from recap.llm import ERROR_KINDS
    from recap.runtime import END_REASONS

    assert tuple(END_REASONS) == kinds.END_REASONS
    assert tuple(ERROR_KINDS) == kinds.LLM_ERROR_KINDS


def test_vocabulary_fields_are_strings_in_arrow_and_known_to_the_writer():
    assert set(vocabularies(EpisodeRecord)) == {"end_reason"}
    assert vocabularies(EpisodeRecord)["end_reason"] == frozenset(kinds.END_REASONS) | {"infra_error"}
    assert set(vocabularies(EventRecord)) == {"source", "kind", "severity"}
    assert set(vocabularies(CallRecord)) == {"status", "error_kind"}
    assert set(vocabularies(NodeRecord)) == {"kind", "status"}
    for table, column in (("episodes", "end_reason"), ("events", "kind"), ("llm_calls", "error_kind"), ("tree_nodes", "status")):
        assert str(arrow_schema(table).field(column).type) == "string"


def test_a_record_outside_its_vocabulary_is_refused_by_its_writer():
    ok = EventRecord(ts=1.0, source="driver", kind="unit_failed", severity="error")
    assert check_vocabulary(ok) is ok
    with pytest.raises(VocabularyError, match=r"EventRecord.kind: 'unit_faild' is not one of"):
        check_vocabulary(EventRecord(ts=1.0, source="driver", kind="unit_faild"))  # type: ignore[arg-type]
    with pytest.raises(VocabularyError, match=r"EventRecord.severity: 'fatal'"):
        check_vocabulary(EventRecord(ts=1.0, source="driver", kind="retry", severity="fatal"))  # type: ignore[arg-type]
    from pipeline.events import EventBuffer

    with pytest.raises(VocabularyError, match=r"EventRecord.kind: 'cap_hit'"):
        EventBuffer().add("cap_hit")  # type: ignore[arg-type]


def test_the_agents_records_meet_the_vocabulary_on_their_way_to_the_sink():
    from workers.episode_worker import RecordForwarder

    sent: list = []
    forward = RecordForwarder("r", sent.append, lambda ref: None, skip_calls=False, batch_rows=1)
    node = NodeRecord(episode_id="e", node_id=0, parent_id=None, depth=0, child_index=0, task="t", kind="root", status="done")
    forward(node)
    with pytest.raises(VocabularyError, match=r"NodeRecord.status: 'finished' is not one of \['done', 'failed', 'open'\]"):
        forward(
            NodeRecord(
                episode_id="e", node_id=1, parent_id=0, depth=1, child_index=0, task="t", kind="primitive", status="finished"
            )
        )  # type: ignore[arg-type]
    forward.close()
    assert [rows["tree_nodes"][0]["status"] for rows in sent] == ["done"]
