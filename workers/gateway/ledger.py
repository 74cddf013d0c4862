"""The run's budget authority: caps that are never exceeded, spend that survives restarts.

Why reserve-then-settle: a call's cost is known only after it returns, and 50 concurrent
callers could each pass a "spend < cap" check and together overshoot. So before a call is
sent, its worst case (prompt-token upper bound + max output tokens, at full input price) is
*reserved*; a reservation that would take committed spend (settled + reserved) past the run
cap or the model's cap is refused (``LLMError("budget")``). After the call the reservation is
*settled* to the actual cost. Every reservation and settlement is an fsync'd journal line
(:class:`workers.gateway.journal.Journal`, ``RUN_DIR/gateway/ledger.jsonl``); a ledger
restarted from the run folder replays it, and reservations left open by a dead process are
settled at their worst case ("orphaned") - so the cap holds across kills too.

A reservation is answered only once it is on disk. The synchronous API (``begin``,
``reserve``) fsyncs inline; the async face (:class:`LocalBudget`, which the gateway core and
the ``BudgetActor`` use) group-commits: the reservation is counted against the caps and
written at once, then the caller awaits :meth:`BudgetLedger.commit`, which concurrent
reservations share (one fdatasync per event-loop tick instead of one each). The caps see
every reservation the moment it is written, so sharing the fsync changes when a call may be
sent, never whether it may.

The ledger is also where results live for idempotency (``call_key`` -> recorded response,
served again with ``served_from="ledger"``) and for the opt-in response cache (request
fingerprint -> response, ``served_from="cache"``). One ledger serves all deployments of a run
(in-process via :class:`LocalBudget`, or behind the Ray ``BudgetActor``). Amounts are integer
pico-dollars (see :mod:`workers.llm.pricing`).

One key: caps, reservations, settlements and spend are kept by the deployment's *name*
(``DeploymentConfig.deployment_name``: the model's unique name in the sweep), never by the
provider model string, so two sweep entries on one model string (two option sets of
``offline/expert``, one model behind two base URLs) have their own caps and spend. Journals
written before name their entries by model string; :mod:`workers.gateway.entries` maps those.
"""

from __future__ import annotations

import threading
import time
from collections import defaultdict
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from schemas.outcomes import BudgetRefusal
from workers.gateway.entries import NAME_FIELD, KeyMap
from workers.gateway.journal import Journal
from workers.gateway.recorded import RecordedResults
from workers.llm.pricing import pico_to_usd, usd_to_pico

JOURNAL_NAME = "gateway/ledger.jsonl"

#: an episode's own cap and what it spent before the call, in pico-USD (see ``BudgetLedger._refusal``)
EpisodeBudget = tuple[int, int]


class BudgetLedger:
    """Budget caps, reservations, settlements and recorded results of one run.

    ``model_caps_usd`` and every ``name`` argument: deployment names. ``provider_models``
    (deployment name -> provider model string, every deployment of the run) lets a journal
    written before entries were kept by name be replayed (:class:`workers.gateway.entries.KeyMap`;
    None: such entries keep their model string)."""

    def __init__(
        self,
        run_dir: Path | str,
        *,
        run_cap_usd: float | None = None,
        model_caps_usd: Mapping[str, float] | None = None,
        fsync: bool = True,
        durable_reservations: bool = True,
        lock_timeout_s: float = 10.0,
        provider_models: Mapping[str, str] | None = None,
    ):
        self.run_dir = Path(run_dir)
        self._lock = threading.RLock()
        self.run_cap = None if run_cap_usd is None else usd_to_pico(run_cap_usd)
        self.model_caps = {m: usd_to_pico(c) for m, c in (model_caps_usd or {}).items()}
        self.spent = 0
        self.spent_by_model: dict[str, int] = defaultdict(int)
        #: rid -> (call_key, deployment name, reserved pico, owner)
        self.open: dict[int, tuple[str, str, int, str]] = {}
        self.reserved = 0
        self.reserved_by_model: dict[str, int] = defaultdict(int)
        #: call_key -> recorded response, fingerprint -> cached response: on disk, filled from the
        #: journal on restore (workers/gateway/recorded.py: a dict grew with every call of the run)
        self.results = RecordedResults()
        self.cache = RecordedResults()
        self.refusals = 0
        self.overruns = 0
        self.late_settles = 0
        self.settled = 0
        self._next_rid = 1
        #: a reservation is answered only once it is fsync'd (machine-crash safe caps); with
        #: False once written (process-kill safe; synced with later entries within a second)
        self.durable_reservations = durable_reservations and fsync
        self._journal = Journal(self.run_dir / JOURNAL_NAME, fsync=fsync, lock_timeout_s=lock_timeout_s)
        self._keys = KeyMap(provider_models, str(self.run_dir / JOURNAL_NAME))
        try:
            self.restored_orphans = self._restore()
        except BaseException:
            self._journal.close()  # a refused journal must not stay locked
            self.results.close()
            self.cache.close()
            raise

    # ---- restore ----
    def _restore(self) -> int:
        for e in self._journal.replay():
            op = e.get("op")
            if op == "reserve":
                self._open(e["rid"], e["key"], self._keys.name_of(e), e["pico"], e.get("owner", ""))
            elif op == "settle":
                self._settle_state(e["rid"], e["pico"], e)
            self._next_rid = max(self._next_rid, int(e.get("rid", 0)) + 1)
        # every reservation still open belonged to a process that is gone
        orphans = list(self.open)
        for rid in orphans:
            self._write_settle(rid, self.open[rid][2], "orphaned")
        return len(orphans)

    # ---- state changes (callers hold the lock) ----
    def _open(self, rid: int, key: str, name: str, pico: int, owner: str) -> None:
        self.open[rid] = (key, name, pico, owner)
        self.reserved += pico
        self.reserved_by_model[name] += pico

    def _settle_state(self, rid: int, pico: int, entry: Mapping[str, Any]) -> None:
        key, name, reserved, _owner = self.open.pop(rid)
        self.reserved -= reserved
        self.reserved_by_model[name] -= reserved
        self.spent += pico
        self.spent_by_model[name] += pico
        self.settled += 1
        if pico > reserved:
            self.overruns += 1
        result = entry.get("result")
        if entry.get("status") == "ok" and result is not None:
            self.results[key] = result
            if entry.get("cache_key"):
                self.cache[entry["cache_key"]] = result

    def _write_settle(self, rid: int, pico: int, status: str, **extra: Any) -> None:
        key, name, _reserved, _owner = self.open[rid]
        entry = {
            "op": "settle",
            "rid": rid,
            "key": key,
            NAME_FIELD: name,
            "pico": int(pico),
            "status": status,
            "t": time.time(),
            **extra,
        }
        self._journal.append(entry)
        self._settle_state(rid, int(pico), entry)

    def _refusal(self, name: str, worst: int | None, episode: EpisodeBudget | None = None) -> BudgetRefusal | None:
        """The cap this call would pass (typed: the driver stops the run or only the model by
        its ``scope``; scope ``episode`` ends only the calling episode), or None when it fits.

        ``episode``: (the episode's cap, what it spent before this call), in pico-USD. The
        episode's calls are sequential, so the caller's own count is exact and the ledger keeps
        no per-episode state. An unpriced call is not refused for the episode's cap alone (it
        costs nothing we can count: a self-hosted model)."""
        if worst is None:
            if self.run_cap is not None or name in self.model_caps:
                return BudgetRefusal("unpriced", name)
            return None
        if self.run_cap is not None and self.spent + self.reserved + worst > self.run_cap:
            return BudgetRefusal("run", name, self.run_cap, self.spent + self.reserved, worst)
        cap = self.model_caps.get(name)
        committed = self.spent_by_model[name] + self.reserved_by_model[name]
        if cap is not None and committed + worst > cap:
            return BudgetRefusal("model", name, cap, committed, worst)
        if episode is not None:
            ep_cap, ep_spent = int(episode[0]), int(episode[1])
            if ep_spent + worst > ep_cap:
                return BudgetRefusal("episode", name, ep_cap, ep_spent, worst)
        return None

    # ---- public API (all amounts pico-USD; results are plain dicts so they cross Ray) ----
    def begin(
        self,
        call_key: str,
        name: str,
        worst_pico: int | None,
        cache_key: str | None = None,
        owner: str = "",
        *,
        defer_sync: bool = False,
        episode: EpisodeBudget | None = None,
    ) -> dict[str, Any]:
        """A recorded result for this call (idempotency / cache), or a reservation, or a refusal.

        A reservation is on disk when this returns, unless ``defer_sync``: then it is written
        (and counted) but the caller must ``await commit()`` before sending the call. A recorded
        result costs nothing, so it is served whatever ``episode`` (see :meth:`_refusal`) says."""
        with self._lock:
            if call_key in self.results:
                return {"status": "recorded", "served_from": "ledger", "result": self.results[call_key]}
            if cache_key is not None and cache_key in self.cache:
                return {"status": "recorded", "served_from": "cache", "result": self.cache[cache_key]}
            return self._reserve(call_key, name, worst_pico, owner, defer_sync, episode)

    def reserve(
        self,
        call_key: str,
        name: str,
        worst_pico: int | None,
        owner: str = "",
        *,
        defer_sync: bool = False,
        episode: EpisodeBudget | None = None,
    ) -> dict[str, Any]:
        """Another reservation for the same call (the previous attempt's was charged)."""
        with self._lock:
            return self._reserve(call_key, name, worst_pico, owner, defer_sync, episode)

    async def commit(self) -> None:
        """Return once every reservation written so far is on disk (group commit: concurrent
        callers share one fdatasync). Nothing to wait for when reservations are not durable."""
        if self.durable_reservations:
            await self._journal.commit()

    def _reserve(
        self,
        call_key: str,
        name: str,
        worst_pico: int | None,
        owner: str,
        defer_sync: bool = False,
        episode: EpisodeBudget | None = None,
    ) -> dict[str, Any]:
        refusal = self._refusal(name, worst_pico, episode)
        if refusal is not None:
            self.refusals += 1
            return {"status": "refused", "message": refusal.message, "refusal": refusal.to_dict()}
        rid = self._next_rid
        self._next_rid += 1
        pico = int(worst_pico or 0)
        self._journal.append(
            {"op": "reserve", "rid": rid, "key": call_key, NAME_FIELD: name, "pico": pico, "owner": owner, "t": time.time()},
            sync=self.durable_reservations and not defer_sync,
        )
        self._open(rid, call_key, name, pico, owner)
        return {"status": "reserved", "rid": rid}

    def settle(
        self,
        rid: int,
        cost_pico: int,
        status: str,
        result: Mapping[str, Any] | None = None,
        cache_key: str | None = None,
        litellm_cost_usd: float | None = None,
    ) -> None:
        """Close a reservation at the actual cost (``status``: ok, error, charged).

        A reservation that is no longer open was settled at its worst case when the ledger
        restarted under a live gateway; the late settlement is counted and dropped (the
        worst case already charged is never less than the actual cost)."""
        with self._lock:
            if rid not in self.open:
                self.late_settles += 1
                return
            extra: dict[str, Any] = {}
            if result is not None:
                extra["result"] = dict(result)
            if cache_key is not None:
                extra["cache_key"] = cache_key
            if litellm_cost_usd is not None:
                extra["litellm_cost_usd"] = litellm_cost_usd
            self._write_settle(rid, cost_pico, status, **extra)

    def charge_worst(self, rid: int) -> int:
        """Settle a reservation at its full amount (an attempt that may have been billed)."""
        with self._lock:
            if rid not in self.open:
                self.late_settles += 1
                return 0
            pico = self.open[rid][2]
            self._write_settle(rid, pico, "charged")
            return pico

    def adopt_orphans(self, deployment: str, keep_owner: str = "") -> int:
        """Settle at worst case the open reservations of a dead gateway of ``deployment``
        (owners are ``<deployment>:<instance>``; ``keep_owner`` is the live instance)."""
        with self._lock:
            dead = [
                rid
                for rid, (_k, _m, _p, owner) in self.open.items()
                if owner.rsplit(":", 1)[0] == deployment and owner != keep_owner
            ]
            for rid in dead:
                self._write_settle(rid, self.open[rid][2], "orphaned")
            return len(dead)

    def set_caps(self, run_cap_usd: float | None = None, model_caps_usd: Mapping[str, float] | None = None) -> None:
        with self._lock:
            if run_cap_usd is not None:
                self.run_cap = usd_to_pico(run_cap_usd)
            for m, c in (model_caps_usd or {}).items():
                self.model_caps[m] = usd_to_pico(c)

    def stats(self) -> dict[str, Any]:
        with self._lock:
            models = set(self.spent_by_model) | set(self.reserved_by_model)
            return {
                "spent_usd": pico_to_usd(self.spent),
                "spent_pico": self.spent,
                "reserved_usd": pico_to_usd(self.reserved),
                "committed_usd": pico_to_usd(self.spent + self.reserved),
                "run_cap_usd": None if self.run_cap is None else pico_to_usd(self.run_cap),
                "model_caps_usd": {m: pico_to_usd(c) for m, c in self.model_caps.items()},
                "by_model_spent_usd": {m: pico_to_usd(self.spent_by_model[m]) for m in sorted(models)},
                "open_reservations": len(self.open),
                "settled": self.settled,
                "refusals": self.refusals,
                "overruns": self.overruns,
                "late_settles": self.late_settles,
                "recorded_results": len(self.results),
                "cached_results": len(self.cache),
                "restored_orphans": self.restored_orphans,
                "journal_syncs": self._journal.syncs,
            }

    def close(self) -> None:
        with self._lock:
            self._journal.close()
            self.results.close()
            self.cache.close()


class LocalBudget:
    """The async face of an in-process :class:`BudgetLedger` (what a gateway core talks to).

    ``group_commit`` (default): a reservation is answered after the shared fdatasync that
    covers it (:meth:`BudgetLedger.commit`); False: each reservation fsyncs on its own, inline
    (the behaviour before group commit, kept for the bench's before/after figures)."""

    def __init__(self, ledger: BudgetLedger, *, owned: bool = True, group_commit: bool = True):
        self.ledger = ledger
        #: close the ledger with the gateway (False when several gateways share it in-process)
        self.owned = owned
        self.group_commit = group_commit

    async def begin(
        self,
        call_key: str,
        name: str,
        worst_pico: int | None,
        cache_key: str | None,
        owner: str,
        episode: EpisodeBudget | None = None,
    ) -> Mapping[str, Any]:
        if not self.group_commit:
            return self.ledger.begin(call_key, name, worst_pico, cache_key, owner, episode=episode)
        answer = self.ledger.begin(call_key, name, worst_pico, cache_key, owner, defer_sync=True, episode=episode)
        return await self._durable(answer)

    async def reserve(
        self, call_key: str, name: str, worst_pico: int | None, owner: str, episode: EpisodeBudget | None = None
    ) -> Mapping[str, Any]:
        if not self.group_commit:
            return self.ledger.reserve(call_key, name, worst_pico, owner, episode=episode)
        return await self._durable(self.ledger.reserve(call_key, name, worst_pico, owner, defer_sync=True, episode=episode))

    async def _durable(self, answer: dict[str, Any]) -> dict[str, Any]:
        """The answer, once its reservation is on disk. If the commit fails or the caller is
        cancelled meanwhile, nobody holds the reservation and nothing was sent under it: it is
        settled at 0 so that it does not hold the cap until a restart."""
        if answer["status"] != "reserved":
            return answer
        try:
            await self.ledger.commit()
        except BaseException:
            self.ledger.settle(answer["rid"], 0, "error")
            raise
        return answer

    async def settle(
        self,
        rid: int,
        cost_pico: int,
        status: str,
        result: Mapping[str, Any] | None,
        cache_key: str | None,
        litellm_cost_usd: float | None,
    ) -> None:
        self.ledger.settle(rid, cost_pico, status, result, cache_key, litellm_cost_usd)

    async def charge_worst(self, rid: int) -> int:
        return self.ledger.charge_worst(rid)

    async def adopt_orphans(self, deployment: str, keep_owner: str) -> int:
        return self.ledger.adopt_orphans(deployment, keep_owner)

    async def stats(self) -> dict[str, Any]:
        return self.ledger.stats()

    async def close(self) -> None:
        if self.owned:
            self.ledger.close()
