"""A small run folder whose episodes called tools (schema version 5), written through PartWriter, and the
same folder as recap wrote it under schema version 4 (no tool_calls table, messages without the tool
columns), for the tests of every reader (recap sql, show, status, report, the viewer).

Episode ``swe-a-1`` is a tool-calling agent: reply 1 calls ``bash`` twice (``ls`` runs, ``sleep 99``
times out), reply 4 calls a tool that does not exist with arguments that are not JSON and carry HTML
(model-written text must come out escaped), reply 6 ends. Episode ``swe-b-1`` is a text-action coding
agent: its one shell command is a tool_calls row without a call id or message.
"""

from __future__ import annotations

import json
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from schemas.parts import PartWriter, part_files
from schemas.records import CallRecord, EpisodeRecord, MessageRecord, RunRecord, StepRecord, ToolCallRecord
from schemas.versions import VERSION_KEY

RUN_ID = "runT"
EVIL_ARGS = '{not json <img src=x onerror="alert(1)">'
CALLS_1 = json.dumps(
    [
        {"id": "c1", "name": "bash", "arguments": '{"command": "ls"}'},
        {"id": "c2", "name": "bash", "arguments": '{"command": "sleep 99"}'},
    ]
)
CALLS_4 = json.dumps([{"id": "c3", "name": "<b>nosuch</b>", "arguments": EVIL_ARGS}])


def _episode(eid: str, unit: str, steps: int, calls: int, end: str) -> EpisodeRecord:
    return EpisodeRecord(
        episode_id=eid,
        unit_id=unit,
        attempt=1,
        benchmark="swe",
        split="lite",
        task="fix",
        instance_id=f"swe/lite/{unit}",
        sampling_seed=0,
        method="react",
        method_config="{}",
        model="scripted",
        end_reason=end,
        success=end == "success",
        steps=steps,
        llm_calls=calls,
        prompt_tokens=0,
        cached_prompt_tokens=0,
        completion_tokens=0,
        cost_usd=0.0,
        wall_s=5.0,
        step_cap=10,
        step_multiplier=4.0,
        worker_id="w0",
        started_at=1.0,
        ended_at=6.0,
        test_double=True,
        label="react",
        provider_model="offline/expert",
    )


EPISODES = [_episode("swe-a-1", "swe-a", 3, 3, "success"), _episode("swe-b-1", "swe-b", 1, 1, "step_cap")]


def _call(eid: str, index: int, window: tuple[int, ...], reply: int) -> CallRecord:
    return CallRecord(eid, index, f"{eid}#{index}", "act", window, "offline/expert", "ok", response_seq=reply, test_double=True)


CALLS = [
    _call("swe-a-1", 0, (0,), 1),
    _call("swe-a-1", 1, (0, 1, 2, 3), 4),
    _call("swe-a-1", 2, (0, 1, 2, 3, 4, 5), 6),
    _call("swe-b-1", 0, (0,), 1),
]
MESSAGES = [
    MessageRecord("swe-a-1", 0, "user", "task", "Fix the failing test in <repo>.", pinned=True),
    MessageRecord("swe-a-1", 1, "assistant", "reply", "", tool_calls=CALLS_1),
    MessageRecord("swe-a-1", 2, "tool", "tool_result", "a.txt\nb.txt", tool_call_id="c1"),
    MessageRecord("swe-a-1", 3, "tool", "tool_result", "error: timed out after 10 s", tool_call_id="c2"),
    MessageRecord("swe-a-1", 4, "assistant", "reply", "Trying <script>x</script>", tool_calls=CALLS_4),
    MessageRecord("swe-a-1", 5, "tool", "tool_result", "error: arguments are not JSON", tool_call_id="c3"),
    MessageRecord("swe-a-1", 6, "assistant", "reply", '{"done": true}'),
    MessageRecord("swe-b-1", 0, "user", "task", "Fix it.", pinned=True),
    MessageRecord("swe-b-1", 1, "assistant", "reply", "cat a.txt"),
]
STEPS = [
    StepRecord("swe-a-1", 0, 1, 'bash {"command": "ls"}', True, "a.txt\nb.txt", False, False),
    StepRecord("swe-a-1", 1, 2, 'bash {"command": "sleep 99"}', True, "error: timed out after 10 s", False, False),
    StepRecord("swe-a-1", 2, 2, f"<b>nosuch</b> {EVIL_ARGS}", False, "error: arguments are not JSON", False, False),
    StepRecord("swe-b-1", 0, 1, "cat a.txt", True, "cat: a.txt: No such file", False, False),
]
TOOL_CALLS = [
    ToolCallRecord("swe-a-1", 0, 0, "bash", '{"command": "ls"}', True, "c1", 1, None, None, 0, 0.25, 12, False),
    ToolCallRecord("swe-a-1", 1, 1, "bash", '{"command": "sleep 99"}', True, "c2", 1, None, None, None, 10.0, 0, True),
    ToolCallRecord("swe-a-1", 2, 2, "<b>nosuch</b>", EVIL_ARGS, False, "c3", 4, error="arguments are not JSON: <img src=x>"),
    ToolCallRecord("swe-b-1", 0, 0, "bash", '{"command": "cat a.txt"}', True, None, None, None, None, 1, 0.5, 30, False),
]
RUN = [RunRecord(1.0, "run: toolrun\n", "hashT", "{}", None, "hostT", "recap run toolrun.yaml")]


def write_tool_run(run_dir: Path) -> Path:
    """The run folder (run.json, plan.json and one part per table)."""
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "run.json").write_text(
        json.dumps({"run_id": RUN_ID, "run": "toolrun", "created_at": 1.0, "schema_version": RUN[0].schema_version})
    )
    units = [
        {
            "unit_id": e.unit_id,
            "key": e.unit_id,
            "instance_id": e.instance_id,
            "method": "react",
            "model": "scripted",
            "sampling_seed": 0,
        }
        for e in EPISODES
    ]
    (run_dir / "plan.json").write_text(json.dumps({"hash_version": 1, "units": units}))
    PartWriter(run_dir, writer="sinkT").write_records(RUN_ID, EPISODES + CALLS + MESSAGES + STEPS + TOOL_CALLS + RUN)
    return run_dir


def as_version_4(run_dir: Path) -> Path:
    """Rewrite a run folder as recap wrote it under schema version 4: every part's version 4 in its
    metadata, messages without ``tool_call_id`` / ``tool_calls``, no ``tool_calls`` folder, run.json
    and the run rows saying 4."""
    run_dir = Path(run_dir)
    for part in sorted(run_dir.glob("*/part-*.parquet")):
        table = part.parent.name
        if table == "tool_calls":
            part.unlink()
            continue
        data = pq.read_table(part)
        if table == "messages":
            data = data.drop_columns(["tool_call_id", "tool_calls"])
        if table == "run":
            data = data.set_column(data.schema.get_field_index("schema_version"), "schema_version", pa.array([4] * data.num_rows))
        pq.write_table(data.replace_schema_metadata({VERSION_KEY: b"4"}), part)
    (run_dir / "tool_calls").rmdir()
    ident = json.loads((run_dir / "run.json").read_text())
    (run_dir / "run.json").write_text(json.dumps({**ident, "schema_version": 4}))
    assert part_files(run_dir, "tool_calls") == []
    return run_dir
