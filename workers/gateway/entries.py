"""What a line of the ledger journal says: the one place that knows the entry format.

Why a module of its own: the ledger writes and replays the journal, and a resume reads it too
(which episodes it names, what an attempt paid) without starting a ledger. Both read the same
format here, so the format can change in one place.

Entries (one JSON object a line, :class:`workers.gateway.journal.Journal`)::

    {"op": "reserve", "rid": 7, "key": "<episode_id>#<call>", "name": "gpt-4o-low", "pico": 1250, "owner": "...", "t": ...}
    {"op": "settle",  "rid": 7, "key": "...", "name": "gpt-4o-low", "pico": 830, "status": "ok", "result": {...}, ...}

``name`` is the deployment's name: the model's unique name in the sweep (its label, or the
model string when it has none), what caps and spend are kept by. Journals written before that
key their entries by the provider model string under ``model`` instead; two sweep entries on one
model string then shared one spend figure. Such an entry is read as the name of the one
deployment serving that model string (:class:`KeyMap`); when several do, its spend cannot be
split between them and the journal is refused (:class:`LedgerKeyError`).
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any

from workers.llm.pricing import pico_to_usd

#: the field a current entry names its deployment by, and the one older entries used
NAME_FIELD = "name"
LEGACY_FIELD = "model"


class LedgerKeyError(RuntimeError):
    """An old journal's entries name a model string that several deployments of the run share."""


def entries(data: bytes | None) -> Iterator[dict[str, Any]]:
    """Every entry of a journal's bytes, skipping a torn or corrupt line (readers that only
    count; the ledger's own replay refuses a corrupt line before the last one)."""
    for line in (data or b"").decode("utf-8", errors="replace").splitlines():
        try:
            e = json.loads(line)
        except ValueError:
            continue
        if isinstance(e, dict):
            yield e


def episode_of(call_key: Any) -> str | None:
    """The episode id a call key (``<episode_id>#<call>``) names, or None."""
    if isinstance(call_key, str) and "#" in call_key:
        return call_key.rsplit("#", 1)[0]
    return None


def episode_ids(data: bytes | None) -> set[str]:
    """The episode ids named by the call keys of a journal."""
    return {eid for e in entries(data) if (eid := episode_of(e.get("key"))) is not None}


@dataclass(frozen=True)
class AttemptSpend:
    """What the ledger journal says one attempt paid: its settled calls, their tokens and cost."""

    calls: int = 0
    prompt_tokens: int = 0
    cached_prompt_tokens: int = 0
    completion_tokens: int = 0
    cost_usd: float = 0.0


def attempt_spend(data: bytes | None, episode_id: str) -> AttemptSpend:
    """The spend of ``episode_id`` by a journal's settlements: every settled reservation whose
    call key is ``<episode_id>#<call>`` counts as a call at its settled cost (failed calls at 0,
    cut ones at their worst case), tokens from the recorded replies."""
    prefix = episode_id + "#"
    calls = prompt = cached = completion = pico = 0
    for e in entries(data):
        if e.get("op") != "settle" or not str(e.get("key", "")).startswith(prefix):
            continue
        calls += 1
        pico += int(e.get("pico") or 0)
        result = e.get("result")
        r: dict[str, Any] = result if isinstance(result, dict) else {}
        prompt += int(r.get("prompt_tokens") or 0)
        cached += int(r.get("cached_prompt_tokens") or 0)
        completion += int(r.get("completion_tokens") or 0)
    return AttemptSpend(calls, prompt, cached, completion, pico_to_usd(pico))


@dataclass(frozen=True)
class JournalSpend:
    """What a run spent by its ledger journal: the one figure every place that prints spend shows.

    ``spent_pico``: the settled reservations (answers at their checked cost, attempts that may
    have been billed and cut or orphaned calls at their worst case, failures at 0) - exactly what
    :class:`workers.gateway.ledger.BudgetLedger` counts against the caps (``spent_usd`` of its
    stats). ``reserved_pico``: reservations still open (calls in flight; after a crash, what the
    next session charges as orphans)."""

    spent_pico: int = 0
    reserved_pico: int = 0
    settled: int = 0

    @property
    def spent_usd(self) -> float:
        return pico_to_usd(self.spent_pico)

    @property
    def reserved_usd(self) -> float:
        return pico_to_usd(self.reserved_pico)


def journal_spend(data: bytes | None) -> JournalSpend:
    """The spend a journal's bytes record (:class:`JournalSpend`), read as the ledger replays it."""
    open_: dict[Any, int] = {}
    spent = settled = 0
    for e in entries(data):
        op = e.get("op")
        if op == "reserve":
            open_[e.get("rid")] = int(e.get("pico") or 0)
        elif op == "settle":
            open_.pop(e.get("rid"), None)
            spent += int(e.get("pico") or 0)
            settled += 1
    return JournalSpend(spent, sum(open_.values()), settled)


class KeyMap:
    """The deployment name an entry is kept under.

    ``provider_models``: deployment name -> provider model string, for every deployment of the
    run (None: unknown - an old entry keeps its model string as its name). An old entry's model
    string maps to the one deployment serving it; served by none (a model no longer in the
    sweep), it stays as is and counts for the run cap only; served by several, it is refused."""

    def __init__(self, provider_models: Mapping[str, str] | None = None, where: str = "ledger journal"):
        self.where = where
        self._by_model: dict[str, list[str]] | None = None
        if provider_models is not None:
            self._by_model = {}
            for name, model in provider_models.items():
                self._by_model.setdefault(model, []).append(name)

    def name_of(self, entry: Mapping[str, Any]) -> str:
        name = entry.get(NAME_FIELD)
        if isinstance(name, str):
            return name
        return self.legacy(str(entry.get(LEGACY_FIELD, "")))

    def legacy(self, model: str) -> str:
        if self._by_model is None:
            return model
        names = self._by_model.get(model, [])
        if len(names) > 1:
            raise LedgerKeyError(
                f"{self.where} was written before spend was kept per model name: its entries name model "
                f"{model!r}, which {', '.join(repr(n) for n in sorted(names))} of this sweep share, so their "
                "spend cannot be split between them; resume with one sweep entry on that model, or use a new output folder"
            )
        return names[0] if names else model


def check_keys(data: bytes | None, provider_models: Mapping[str, str], where: str = "ledger journal") -> None:
    """Raise :class:`LedgerKeyError` (one line) when an old journal cannot be read under
    ``provider_models`` (see :class:`KeyMap`); nothing to check in a current one."""
    keys = KeyMap(provider_models, where)
    for e in entries(data):
        if e.get("op") in ("reserve", "settle"):
            keys.name_of(e)
