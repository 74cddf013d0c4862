"""The terminal ``episodes`` row of an attempt, from the unit and its typed outcome.

Why in its own module: the row is the run's ground truth (success tables, resume, status all
read it), so how it is assembled - the end reason an infrastructure failure gets, the error's
kind prefix, the spend of an attempt whose worker died - is one pure function, tested alone.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypedDict

from pipeline.resume import INFRA_ERROR, INFRA_ERROR_KINDS, AttemptSpend, infra_failure
from pipeline.units import Unit
from schemas.kinds import RowEndReason
from schemas.outcomes import EnvFacts, EpisodeOutcome, EpisodeResult
from schemas.records import EpisodeRecord
from schemas.tables import check_vocabulary
from workers.envs.registry import place_of

#: an attempt's spend by the ledger journal (None: not known), for attempts without a result
JournalSpend = Callable[[str], AttemptSpend | None]


def episode_record(
    unit: Unit,
    attempt: int,
    outcome: EpisodeOutcome | None,
    *,
    end_reason: RowEndReason | None = None,
    error: str | None = None,
    worker_id: str | None = None,
    started: float = 0.0,
    journal_spend: JournalSpend | None = None,
    now: float | None = None,
) -> EpisodeRecord:
    """The terminal row of an attempt (schema version 2).

    The arm's method, label, profile and ablation apart; the place from
    :func:`workers.envs.registry.place_of`, as the benchmark places it (ALFWorld one split; a row without an environment still has
    its split and task); an infrastructure failure ends ``infra_error`` with its kind first in
    the error; an attempt without a result (a unit given up on) gets the spend the ledger
    journal recorded for it."""
    res: EpisodeResult | None = outcome.result if outcome is not None else None
    env = outcome.env if outcome is not None else EnvFacts(unit.benchmark)
    now = time.time() if now is None else now
    end_reason, error = _ending(unit, attempt, res, end_reason, error)
    if res is not None:
        calls, prompt, cached, completion, cost = (
            res.llm_calls,
            res.prompt_tokens,
            res.cached_prompt_tokens,
            res.completion_tokens,
            res.cost_usd,
        )
    else:
        calls, prompt, cached, completion, cost = _journal_usage(journal_spend, f"{unit.unit_id}-{attempt}")
    bench, split, task = place_of(unit.instance_id, env.split or None, env.task or None)
    return check_vocabulary(
        EpisodeRecord(
            **_unit_fields(unit, attempt),
            benchmark=env.benchmark or bench,
            split=split,
            task=task,
            end_reason=end_reason,
            success=bool(res.success) if res is not None else False,
            steps=res.steps if res is not None else 0,
            llm_calls=int(calls),
            prompt_tokens=int(prompt),
            cached_prompt_tokens=int(cached),
            completion_tokens=int(completion),
            cost_usd=float(cost),
            wall_s=float(outcome.wall_s if outcome is not None else (now - started if started else 0.0)),
            step_cap=int(env.max_steps or 0),
            optimal_steps=env.optimal_steps,
            max_depth=res.max_depth if res is not None else 0,
            error=error,
            worker_id=(outcome.worker_id if outcome is not None else None) or worker_id,
            started_at=float(outcome.started_at if outcome is not None else started),
            ended_at=float(outcome.ended_at if outcome is not None else now),
            test_double=outcome.test_double if outcome is not None else unit.model.startswith("offline/"),
        )
    )


class _UnitColumns(TypedDict):
    episode_id: str
    unit_id: str
    attempt: int
    instance_id: str
    sampling_seed: int
    method: str
    method_config: str
    model: str
    step_multiplier: float
    label: str
    profile: str | None
    ablation: str | None
    provider_model: str | None


def _unit_fields(unit: Unit, attempt: int) -> _UnitColumns:
    """The row's columns that come from the unit and attempt alone (its identity and arm)."""
    return _UnitColumns(
        episode_id=f"{unit.unit_id}-{attempt}",
        unit_id=unit.unit_id,
        attempt=attempt,
        instance_id=unit.instance_id,
        sampling_seed=unit.sampling_seed,
        method=unit.method,
        method_config=unit.recorded_config,
        model=unit.model_label,
        step_multiplier=unit.step_multiplier,
        label=unit.method_label,
        profile=unit.profile,
        ablation=unit.ablation_name,
        provider_model=unit.model,
    )


def _ending(
    unit: Unit, attempt: int, res: EpisodeResult | None, end_reason: RowEndReason | None, error: str | None
) -> tuple[RowEndReason, str | None]:
    """The row's end reason and error: the given ones, else the result's; an LLM error names its
    kind first, and an infrastructure failure ends ``infra_error``."""
    if end_reason is None:
        if res is None:
            raise ValueError(f"attempt {unit.unit_id}-{attempt}: no result and no end reason")
        end_reason = res.end_reason
    if error is None and res is not None:
        error = res.error
        kind = res.error_kind
        # the row's error names the LLM error kind first: what makes an infrastructure
        # failure recognisable (and retryable) from the table alone
        if end_reason == "llm_error" and kind in INFRA_ERROR_KINDS and not (error or "").startswith(f"{kind}:"):
            error = f"{kind}: {error or ''}".rstrip()
    if infra_failure(end_reason, error) is not None:
        end_reason = INFRA_ERROR
    return end_reason, error


def _journal_usage(journal_spend: JournalSpend | None, episode_id: str) -> tuple[int, int, int, int, float]:
    """(calls, prompt, cached prompt, completion tokens, cost) of an attempt without a result, by
    the ledger journal (zeros when it has none)."""
    s = _safe(journal_spend, episode_id)
    if s is None:
        return 0, 0, 0, 0, 0.0
    return s.calls, s.prompt_tokens, s.cached_prompt_tokens, s.completion_tokens, s.cost_usd


def _safe(journal_spend: JournalSpend | None, episode_id: str) -> AttemptSpend | None:
    if journal_spend is None:
        return None
    try:
        return journal_spend(episode_id)
    except Exception:  # the row matters more than its spend
        return None
