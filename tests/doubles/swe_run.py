"""A small run folder of coding episodes (SWE-bench), written through PartWriter, for the report's coding
section and the paper's SWE-bench Verified row (tests/reports/test_coding_report.py).

What it holds (model ``gpt-4.1``, provider model ``openai/gpt-4.1-2025-04-14``, profile ``paper``,
temperature 0 unless noted):

* ``swe-verified`` (split ``test``, each instance its own task), four instances ``django__django-1..4``,
  three arms: ``recap`` (method recap), ``mini_swe`` (method mini_swe) and ``react`` (method react,
  temperature 0.5). :data:`VERIFIED` lists each episode: end reason, tool calls, cost, and its
  evaluation (reason, ours, official) or None when it was never evaluated.
* ``swe`` (the fixture tasks, split ``custom``): one ``recap`` arm on two tasks.

With ``full=True`` the ``recap`` and ``mini_swe`` arms instead ran all 500 SWE-bench Verified instances
once (224 and 198 resolved: the paper's 44.8 and 39.6), one tool call each, every one evaluated, and the
``react`` and ``swe`` arms are left out.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path

from schemas.parts import PartWriter
from schemas.records import EpisodeRecord, EvaluationRecord, RunRecord, StepRecord, ToolCallRecord

RUN_ID = "runS"
MODEL = "gpt-4.1"
PROVIDER_MODEL = "openai/gpt-4.1-2025-04-14"

#: (arm, method, instance, end_reason, tool calls, cost, (reason, ours_resolved, official_resolved) or None)
Episode = tuple[str, str, str, str, int, float, tuple[str, bool, bool | None] | None]
VERIFIED: tuple[Episode, ...] = (
    ("recap", "recap", "django__django-1", "success", 3, 0.5, ("resolved", True, True)),
    ("recap", "recap", "django__django-2", "agent_done", 12, 1.25, ("tests_failed", False, False)),
    ("recap", "recap", "django__django-3", "success", 120, 4.0, ("resolved", True, True)),
    ("recap", "recap", "django__django-4", "step_cap", 30, 2.0, ("no_patch", False, None)),
    ("mini_swe", "mini_swe", "django__django-1", "success", 5, 0.25, ("resolved", True, True)),
    ("mini_swe", "mini_swe", "django__django-2", "agent_done", 8, 0.5, ("patch_failed", False, None)),
    ("mini_swe", "mini_swe", "django__django-3", "llm_error", 40, 1.0, None),
    ("mini_swe", "mini_swe", "django__django-4", "agent_done", 250, 3.0, ("tests_failed", True, False)),
    ("react", "react", "django__django-1", "agent_done", 15, 0.75, ("timeout", False, None)),
    ("react", "react", "django__django-2", "budget_exhausted", 60, 3.5, None),
    ("react", "react", "django__django-3", "success", 20, 1.5, ("resolved", True, True)),
    ("react", "react", "django__django-4", "json_failures", 2, 0.1, None),
)
FIXTURE: tuple[Episode, ...] = (
    ("recap", "recap", "add", "success", 4, 0.0, ("resolved", True, None)),
    ("recap", "recap", "greet", "agent_done", 6, 0.0, ("tests_failed", False, None)),
)
#: SWE-bench Verified instances of the full run, and how many of them each arm resolved
FULL_INSTANCES = 500
FULL_RESOLVED = {"recap": 224, "mini_swe": 198}


def _episode(bench: str, split: str, ep: Episode, temperature: float) -> EpisodeRecord:
    arm, method, inst, end, _, cost, _ = ep
    unit = f"{bench}-{arm}-{inst}"
    return EpisodeRecord(
        episode_id=f"{unit}-1",
        unit_id=unit,
        attempt=1,
        benchmark=bench,
        split=split,
        task=inst,
        instance_id=f"{bench}/{inst}",
        sampling_seed=0,
        method=method,
        method_config=json.dumps({"temperature": temperature}),
        model=MODEL,
        end_reason=end,  # type: ignore[arg-type]
        success=end == "success",
        steps=ep[4],
        llm_calls=ep[4] + 1,
        prompt_tokens=100,
        cached_prompt_tokens=0,
        completion_tokens=10,
        cost_usd=cost,
        wall_s=5.0,
        step_cap=250,
        step_multiplier=1.0,
        worker_id="w0",
        started_at=1.0,
        ended_at=6.0,
        test_double=False,
        label=arm,
        profile="paper",
        provider_model=PROVIDER_MODEL,
    )


def _tool_calls(eid: str, n: int) -> list[ToolCallRecord]:
    return [ToolCallRecord(eid, i, i, "bash", json.dumps({"command": f"echo {i}"}), True, exit_code=0) for i in range(n)]


def _evaluation(eid: str, inst: str, verdict: tuple[str, bool, bool | None]) -> EvaluationRecord:
    reason, ours, official = verdict
    return EvaluationRecord(
        episode_id=eid,
        instance_id=inst,
        resolved=reason == "resolved",
        reason=reason,
        graded_by="ours" if official is None else "official",
        grading="both",
        ours_resolved=ours,
        tests="{}",
        fail_to_pass_passed=0,
        fail_to_pass_total=1,
        pass_to_pass_passed=0,
        pass_to_pass_total=0,
        patch="",
        patch_bytes=0,
        log="",
        log_bytes=0,
        duration_s=1.0,
        official_resolved=official,
        official_status=None if official is None else ("RESOLVED_FULL" if official else "RESOLVED_NO"),
    )


def episodes(full: bool = False) -> list[tuple[str, str, Episode, float]]:
    """Every episode of the run as (benchmark, split, episode, temperature)."""
    if full:
        out = []
        for arm, k in FULL_RESOLVED.items():
            for i in range(FULL_INSTANCES):
                won = i < k
                verdict = ("resolved", True, True) if won else ("tests_failed", False, False)
                ep = (arm, arm, f"repo__repo-{i:03d}", "success" if won else "agent_done", 1, 1.0, verdict)
                out.append(("swe-verified", "test", ep, 0.0))
        return out
    return [("swe-verified", "test", ep, 0.5 if ep[0] == "react" else 0.0) for ep in VERIFIED] + [
        ("swe", "custom", ep, 0.0) for ep in FIXTURE
    ]


def write_swe_run(
    run_dir: Path,
    *,
    full: bool = False,
    extra: Sequence[tuple[str, str, Episode, float]] = (),
    steps: Mapping[str, Sequence[tuple[str, str]]] | None = None,
) -> Path:
    """The run folder (run.json, plan.json and one part per table); ``extra`` episodes (as
    :func:`episodes` gives them) after the others; ``steps``: by episode id, its steps' (action,
    observation), all valid."""
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    records: list[object] = []
    units = []
    for bench, split, ep, temperature in [*episodes(full), *extra]:
        rec = _episode(bench, split, ep, temperature)
        records.append(rec)
        records.extend(_tool_calls(rec.episode_id, ep[4]))
        for i, (action, observation) in enumerate((steps or {}).get(rec.episode_id, ())):
            records.append(StepRecord(rec.episode_id, i, i + 1, action, True, observation, False, False))
        if ep[6] is not None:
            records.append(_evaluation(rec.episode_id, rec.instance_id, ep[6]))
        units.append(
            {
                "unit_id": rec.unit_id,
                "key": rec.unit_id,
                "instance_id": rec.instance_id,
                "method": rec.label,
                "method_name": rec.method,
                "model": MODEL,
                "sampling_seed": 0,
            }
        )
    records.append(RunRecord(1.0, "run: swerun\n", "hashS", "{}", None, "hostS", "recap run swerun.yaml"))
    (run_dir / "run.json").write_text(
        json.dumps({"run_id": RUN_ID, "run": "swerun", "created_at": 1.0, "schema_version": RunRecord.schema_version})
    )
    (run_dir / "plan.json").write_text(json.dumps({"hash_version": 1, "units": units}))
    PartWriter(run_dir, writer="sinkS").write_records(RUN_ID, records)  # type: ignore[arg-type]
    return run_dir
