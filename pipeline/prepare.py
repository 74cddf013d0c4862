"""Checks a sweep before anything is written: the expanded plan, keys and prices, the output folder.

Everything that can fail before a session does so here, with one line, so that a refused sweep
leaves no trace in its folder.
"""

from __future__ import annotations

from dataclasses import dataclass

from pipeline.errors import SpecError
from pipeline.preflight import preflight
from pipeline.resume import check_journal
from pipeline.spec import SweepSpec, parse_spec
from pipeline.store import PLAN_FILE, SPEC_FILE, RunIdentity, RunStore
from pipeline.units import Plan, PlanDiff, diff_plans, expand, keep_earlier_ids


@dataclass
class Prepared:
    """A sweep checked and ready to start: its expanded plan and output store. ``identity`` and ``diff`` are None
    for a fresh folder; for an existing run they are its run.json and how the new plan differs from the stored
    one."""

    spec: SweepSpec
    spec_text: str
    plan: Plan
    store: RunStore
    identity: RunIdentity | None
    diff: PlanDiff | None


def prepare(spec: SweepSpec, spec_text: str, *, check_keys: bool = True) -> Prepared:
    """Expand and check a sweep: units, keys, prices, the output folder. Writes nothing."""
    plan = expand(spec)
    if check_keys:
        preflight(spec)
    store = RunStore(spec.output)
    store.check_unlocked()  # first: a driver starting in a fresh folder has only its lock there
    ident = store.check_can_hold(spec.run)
    if ident is not None:
        # a corrupt ledger journal, or an old one whose spend this sweep cannot split: one line now
        check_journal(store, {m.name: m.model for m in spec.models})
    diff = None
    if ident is not None:
        old = store.read_json(PLAN_FILE)
        plan = keep_earlier_ids(plan, old, stored_spec(store))
        diff = diff_plans(old, plan)
    return Prepared(spec, spec_text, plan, store, ident, diff)


def stored_spec(store: RunStore) -> SweepSpec | None:
    """The spec.yaml a run folder holds (the last session's), or None when it has none or it does
    not read: what a run written before environment options were in the unit id ran with."""
    try:
        text = store.read_text(SPEC_FILE)
        return parse_spec(text, SPEC_FILE) if text is not None else None
    except (SpecError, OSError, ValueError):
        return None
