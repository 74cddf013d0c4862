"""One gateway shard's side of the shared quota: a window share and a dollar lease, spent locally.

A sharded deployment runs N :class:`workers.gateway.core.DeploymentGateway` (one per shard
actor); each gets two objects in place of its own quota and budget:

- :class:`ShardAdmission`, its admission controller: the same sliding windows, concurrency and
  Retry-After handling as a single gateway (:class:`workers.gateway.limits.AdmissionController`),
  with the RPM/TPM limits set to the *share* this shard holds from the quota authority
  (:class:`workers.gateway.quota.QuotaBook`). A renewal task keeps the share: it asks for more
  when callers wait for window room, hands back slack when idle, and renews before the grant
  lapses. Past its lapse the shard admits nothing (the authority lets the share drain).
- :class:`LeasedBudget`, its budget authority: the budget protocol of
  :class:`workers.gateway.ledger.LocalBudget` (begin, reserve, settle, charge_worst, ...) served
  out of a dollar lease (:class:`workers.gateway.quota.LeaseLedger`) without a round trip per
  call. Calls are reported to the authority in batches (every ``report_s``, or
  ``report_calls`` calls, or when the lease runs short). Per-call round trips remain where the
  answer lives only at the authority: a call key that has a recorded result there (a re-sent
  call after a restart), a call with the response cache on (``cache_key``: the cache spans every
  shard), an unpriced call, and the last calls once the headroom no longer allows a lease of one
  worst case (reserved one by one, as a single gateway does).

``quota`` is the authority's async face: :class:`workers.gateway.quota.LocalQuota` in-process,
or ``RemoteQuota`` over Ray (:mod:`workers.gateway.actors`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

from schemas.outcomes import BudgetRefusal
from workers.gateway.core import DeploymentGateway
from workers.gateway.ledger import EpisodeBudget
from workers.gateway.limits import AdmissionController, AdmissionError, Ticket
from workers.gateway.quota import chunk, fair_share
from workers.llm.pricing import PriceTable
from workers.llm.providers import DeploymentConfig

log = logging.getLogger(__name__)


def shard_tag(deployment: str, index: int) -> str:
    """The owner prefix of a shard's reservations and leases (``adopt_orphans`` charges those of a
    dead incarnation of the same shard, never a live sibling's)."""
    return f"{deployment}#s{index}"


class ShardAdmission(AdmissionController):
    """An admission controller whose RPM/TPM limits are this shard's share of the deployment's
    quota (see the module docstring). ``rpm`` / ``tpm``: the deployment's whole quota."""

    def __init__(
        self,
        quota: Any,
        deployment: str,
        shard: str,
        shards: int,
        *,
        rpm: int | None,
        tpm: int | None,
        window_s: float,
        pad_s: float,
        max_concurrency: int,
        rate_limit_default_wait_s: float = 5.0,
        anchor: str = "response",
        clock: Callable[[], float] = time.monotonic,
    ):
        super().__init__(
            rpm=None if rpm is None else 0,
            tpm=None if tpm is None else 0,
            window_s=window_s,
            pad_s=pad_s,
            max_concurrency=max_concurrency,
            rate_limit_default_wait_s=rate_limit_default_wait_s,
            anchor=anchor,
            clock=clock,
        )
        self.quota = quota
        self.deployment = deployment
        self.shard = shard
        self.shards = shards
        self.quota_rpm = rpm
        self.quota_tpm = tpm
        #: admissions stop at this (monotonic) time unless the share is renewed
        self.valid_until = float("inf") if rpm is None and tpm is None else float("-inf")
        self._demand = asyncio.Event()
        self._renewed = asyncio.Event()
        self._need_tokens = 0
        self._used = False
        self._renewer: asyncio.Task | None = None
        self._gap_s = max(0.01, (window_s + pad_s) / 50)
        self.lease_calls = 0

    # ---- admission ----
    def _check_size(self, tokens: int) -> None:
        if self.quota_tpm is not None and tokens > self.quota_tpm:
            raise AdmissionError(
                f"request needs {tokens} tokens (prompt + max output), more than the deployment's TPM limit {self.quota_tpm}"
            )

    async def acquire(self, tokens: int) -> Ticket:
        self._check_size(tokens)
        self._used = True
        if self._renewer is None and self.valid_until != float("inf"):
            self._renewer = asyncio.get_running_loop().create_task(self._renew_loop())
        while True:
            if self._clock() >= self.valid_until:  # no valid share: wait for the renewal
                self._demand.set()
                self._renewed.clear()
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(self._renewed.wait(), 1.0)
                continue
            self._need_tokens = max(self._need_tokens, tokens)
            ticket = await super().acquire(tokens)
            if self._clock() < self.valid_until:
                return ticket
            self.cancel(ticket)  # admitted past the lapse: not sent

    async def _sleep_interruptibly(self, seconds: float) -> None:
        """Waiting for window room: the share is short, so the renewal task asks for more."""
        self._demand.set()
        await super()._sleep_interruptibly(seconds)

    # ---- the share ----
    def _slack(self, window: Any) -> int:
        if window.limit is None:
            return 0
        _, total = window.usage(self._clock())
        return max(0, window.limit - total)

    def _plan(self, first: bool, demand: bool) -> tuple[tuple[int, int], tuple[int, int]]:
        """(give, want) in (requests, tokens) for the next renewal."""
        if first:
            return (0, 0), (fair_share(self.quota_rpm, self.shards), fair_share(self.quota_tpm, self.shards))
        if demand:
            need_tok = max(0, self._need_tokens - self._slack(self.tokens))
            want_tok = 0 if self.quota_tpm is None else max(chunk(self.quota_tpm, self.shards), need_tok)
            return (0, 0), (chunk(self.quota_rpm, self.shards), want_tok)
        # idle since the last renewal: every unused slot goes back; otherwise keep one chunk spare
        keep_r = 0 if not self._used else chunk(self.quota_rpm, self.shards)
        keep_t = 0 if not self._used else chunk(self.quota_tpm, self.shards)
        return (max(0, self._slack(self.requests) - keep_r), max(0, self._slack(self.tokens) - keep_t)), (0, 0)

    async def _renew_loop(self) -> None:
        first = True
        renew_s = 1.0
        while True:
            if not first:
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(self._demand.wait(), renew_s)
            demand = self._demand.is_set() and (bool(self._waiters) or self.active > 0 or self._need_tokens > 0)
            self._demand.clear()
            give, want = self._plan(first, demand)
            if not demand:
                self._need_tokens = 0
            self._used = False
            # the slack given back leaves this shard's limits before the authority hears of it
            if self.requests.limit is not None:
                self.requests.limit -= give[0]
            if self.tokens.limit is not None:
                self.tokens.limit -= give[1]
            sent = self._clock()
            try:
                answer = await self.quota.window_lease(self.deployment, self.shard, give, want)
            except asyncio.CancelledError:
                raise
            except Exception as exc:  # the authority is away: the share lapses, admissions stop
                log.warning("shard %s could not renew its quota share: %s: %s", self.shard, type(exc).__name__, exc)
                await asyncio.sleep(max(self._gap_s, 0.5))
                continue
            self.lease_calls += 1
            if self.requests.limit is not None:
                self.requests.limit = int(answer["requests"])
            if self.tokens.limit is not None:
                self.tokens.limit = int(answer["tokens"])
            self.valid_until = sent + float(answer["valid_s"])
            renew_s = float(answer["valid_s"]) / 3
            first = False
            self._window_changed.set()
            self._wake()
            self._renewed.set()
            await asyncio.sleep(self._gap_s)

    async def aclose(self) -> None:
        """Stop renewing and hand the share back (it drains for one window span)."""
        if self._renewer is not None:
            self._renewer.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self._renewer
            self._renewer = None
            self.valid_until = float("-inf")
            with contextlib.suppress(Exception):
                await self.quota.window_release(self.deployment, self.shard)

    # ---- control ----
    def set_limits(self, *, rpm: int | None = None, tpm: int | None = None, max_concurrency: int | None = None) -> None:
        """Concurrency is the shard's own; RPM/TPM belong to the quota authority (unchanged here)."""
        if rpm is not None or tpm is not None:
            log.warning("shard %s: rpm/tpm of a sharded deployment are set at the quota authority; ignored", self.shard)
        super().set_limits(max_concurrency=max_concurrency)

    def stats(self) -> dict:
        out = super().stats()
        out["rpm_share"], out["tpm_share"] = out["rpm"], out["tpm"]
        out["rpm"], out["tpm"] = self.quota_rpm, self.quota_tpm
        out["shard"] = self.shard
        out["lease_calls"] = self.lease_calls
        return out


class LeasedBudget:
    """The budget protocol a gateway core expects, served out of a dollar lease (module docstring).

    ``tag``: :func:`shard_tag` (or the deployment's name for the single gateway of a pipeline
    run); reservations and leases are owned by ``<tag>:<instance>``.

    ``keep_worst`` (None: a shard's behaviour, the lease grows with the calls in flight and goes
    back only when idle): the unused part of the lease is kept within that many worst cases -
    each report hands back the rest and tops it up when it fell below one worst case, and an ask
    for more hands back what was left - so that a crash charges (the lease in full) at most
    that much beyond the worst cases of the calls in flight, and a call refused at the
    authority near a cap sees the same headroom a gateway without a lease would."""

    def __init__(
        self,
        quota: Any,
        deployment: str,
        tag: str,
        *,
        report_s: float = 0.5,
        report_calls: int = 64,
        keep_worst: int | None = None,
    ):
        self.quota = quota
        self.deployment = deployment
        self.tag = tag
        self.owner = f"{tag}:{uuid.uuid4().hex[:8]}"
        self.report_s = report_s
        self.report_calls = report_calls
        self.keep_worst = keep_worst
        self.lease: int | None = None
        #: pico-USD of the lease neither reserved nor spent by a call in flight
        self.avail = 0
        self.gen = 0  # bumped when the authority lost the lease (its money was charged in full)
        self.pending: list[tuple] = []
        self._recent: dict[str, Any] = {}  # results settled here, not yet reported
        self.known: set[str] | None = None  # call keys with a result recorded at the authority
        self._local: dict[str, tuple[str, int, int]] = {}  # local rid -> (call key, worst, gen)
        self._next = 0
        self._sized = 0  # the biggest worst case reserved here: what a lease is sized for
        self._used = False
        self._short = False  # the last ask got no lease: calls go one by one to the authority for now
        self._lock = asyncio.Lock()
        self._kick = asyncio.Event()
        self._loop_task: asyncio.Task | None = None
        #: calls reserved out of the lease / at the authority; reports sent; reports that asked for more
        self.counts = {"local": 0, "remote": 0, "reports": 0, "asks": 0}

    # ---- the budget protocol ----
    async def _known(self) -> set[str]:
        if self.known is None:
            self.known = set(await self.quota.recorded_keys())
        return self.known

    async def begin(
        self,
        call_key: str,
        name: str,
        worst_pico: int | None,
        cache_key: str | None,
        owner: str,
        episode: EpisodeBudget | None = None,
    ) -> Any:
        known = await self._known()
        if call_key in self._recent:
            return {"status": "recorded", "served_from": "ledger", "result": self._recent[call_key]}
        if cache_key is not None or worst_pico is None or call_key in known:
            self.counts["remote"] += 1
            return await self.quota.begin(call_key, name, worst_pico, cache_key, self.owner, episode)
        return await self._reserve(call_key, name, worst_pico, episode)

    async def reserve(
        self, call_key: str, name: str, worst_pico: int | None, owner: str, episode: EpisodeBudget | None = None
    ) -> Any:
        if worst_pico is None:
            self.counts["remote"] += 1
            return await self.quota.reserve(call_key, name, worst_pico, self.owner, episode)
        return await self._reserve(call_key, name, worst_pico, episode)

    async def _reserve(self, call_key: str, name: str, worst: int, episode: EpisodeBudget | None) -> Any:
        if episode is not None and int(episode[1]) + worst > int(episode[0]):  # stateless: the caller counts
            refusal = BudgetRefusal("episode", name, int(episode[0]), int(episode[1]), worst)
            return {"status": "refused", "message": refusal.message, "refusal": refusal.to_dict()}
        self._used = True
        self._sized = max(self._sized, worst)
        if self.avail < worst and not self._short:  # a lease sized for the biggest call seen, so that one serves many
            await self._report(want_worst=self._sized)
            self._short = self.avail < worst  # no lease to be had: ask again only after the next report tick
        if self.avail >= worst:
            self.avail -= worst
            self._next += 1
            rid = f"L{self._next}"
            self._local[rid] = (call_key, worst, self.gen)
            self.counts["local"] += 1
            return {"status": "reserved", "rid": rid}
        # headroom too short for a lease: this call is reserved at the authority on its own
        self.counts["remote"] += 1
        return await self.quota.reserve(call_key, name, worst, self.owner, episode)

    async def settle(
        self, rid: Any, cost_pico: int, status: str, result: Any, cache_key: str | None, litellm_cost_usd: float | None
    ) -> None:
        if not isinstance(rid, str):
            await self.quota.settle(rid, cost_pico, status, result, cache_key, litellm_cost_usd)
            return
        key, worst, gen = self._local.pop(rid)
        if gen == self.gen:  # a lost lease's money was charged in full: nothing comes back
            self.avail += worst - int(cost_pico)
        self.pending.append((key, int(cost_pico), status, result, cache_key, litellm_cost_usd))
        if status == "ok" and result is not None:
            self._recent[key] = result
        if len(self.pending) >= self.report_calls or self._over_keep(2):
            self._kick.set()

    def _over_keep(self, factor: int = 1) -> bool:
        """The unused lease is more than ``factor`` x ``keep_worst`` worst cases (never, without a keep)."""
        return self.keep_worst is not None and self._sized > 0 and self.avail > factor * self.keep_worst * self._sized

    def _low(self) -> bool:
        """Less than one worst case left unused, with a keep: the next report asks for more before a call must."""
        return self.keep_worst is not None and self._sized > 0 and self.avail < self._sized

    async def charge_worst(self, rid: Any) -> int:
        if not isinstance(rid, str):
            return int(await self.quota.charge_worst(rid))
        worst = self._local[rid][1]
        await self.settle(rid, worst, "charged", None, None, None)
        return worst

    async def adopt_orphans(self, deployment: str, keep_owner: str) -> int:
        """The open reservations and leases of this shard's dead incarnations, charged in full;
        starts the reporting task (called once, on the gateway's loop)."""
        if self._loop_task is None:
            self._loop_task = asyncio.get_running_loop().create_task(self._report_loop())
        return int(await self.quota.adopt_orphans(self.tag, self.owner))

    async def stats(self) -> dict[str, Any]:
        return dict(await self.quota.stats())

    async def close(self) -> None:
        """Report what is pending and hand the unused lease back."""
        if self._loop_task is not None:
            self._loop_task.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self._loop_task
            self._loop_task = None
        await self._report(give_all=True)
        await self.quota.close()

    # ---- reports ----
    async def _report_loop(self) -> None:
        while True:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._kick.wait(), self.report_s)
            self._kick.clear()
            self._short = False
            idle = not self._used
            self._used = False
            trim = not idle and self._over_keep()
            top_up = not idle and self._low()
            if self.pending or (idle and self.avail > 0) or trim or top_up:
                try:
                    await self._report(give_all=idle, want_worst=self._sized if top_up else 0, trim=trim)
                except Exception as exc:  # the authority is away: the calls stay pending
                    log.warning("shard %s could not report to the quota authority: %s: %s", self.tag, type(exc).__name__, exc)

    async def report_now(self) -> None:
        """Report the calls settled so far (the spend the authority shows is then exact)."""
        if self.pending:
            await self._report()

    async def _report(self, *, want_worst: int = 0, give_all: bool = False, trim: bool = False) -> None:
        async with self._lock:
            if want_worst > 0 and self.avail >= want_worst:
                return  # a concurrent report already brought enough
            calls, self.pending = self.pending, []
            if self.lease is None and not calls and want_worst == 0:
                return
            give = 0
            if give_all or (want_worst > 0 and self.keep_worst is not None):
                give = self.avail  # an ask hands back the rest: less than the worst case it asks for
            elif trim and self.keep_worst is not None:
                give = max(0, self.avail - self.keep_worst * self._sized)
            self.avail -= give
            try:
                answer = await self.quota.report(self.lease, self.deployment, self.owner, calls, give, want_worst)
            except BaseException:
                self.pending[:0] = calls  # not written: sent again with the next report
                self.avail += give
                raise
            self.counts["reports"] += 1
            self.counts["asks"] += want_worst > 0
            if answer.get("lost"):
                self.gen += 1
                self.avail = 0
            old = self.lease
            self.lease = answer["lease"]
            # what the authority's new lease holds beyond this shard's own accounting is the grant
            self.avail = max(0, int(answer["pico"]) - self._held_under_lease()) if self.lease is not None else 0
            if old is None and self.lease is None:
                self.avail = 0
            known = self.known if self.known is not None else set()
            for key, _cost, status, result, _ck, _pc in calls:
                if status == "ok" and result is not None:
                    known.add(key)
                    self._recent.pop(key, None)
            self.known = known

    def _held_under_lease(self) -> int:
        """Worst cases of this lease generation's calls in flight, plus the costs settled since the report was sent."""
        return sum(w for (_k, w, g) in self._local.values() if g == self.gen) + sum(int(c[1]) for c in self.pending)


class ShardGateway(DeploymentGateway):
    """A :class:`DeploymentGateway` serving shard ``index`` of ``shards`` of its deployment:
    its admission is a :class:`ShardAdmission`, its budget a :class:`LeasedBudget` on ``quota``.
    The in-flight limit is split between the shards (``max_concurrency / shards``, rounded up)."""

    def __init__(
        self,
        config: DeploymentConfig,
        *,
        index: int,
        shards: int,
        quota: Any,
        run_dir: Path | str,
        run_id: str | None = None,
        prices: PriceTable | None = None,
    ):
        name = config.deployment_name
        tag = shard_tag(name, index)
        admission = ShardAdmission(
            quota,
            name,
            f"{tag}:{uuid.uuid4().hex[:8]}",  # per incarnation: a restart never takes its predecessor's share
            shards,
            rpm=config.rpm,
            tpm=config.tpm,
            window_s=config.window_s,
            pad_s=config.window_pad_s,
            max_concurrency=max(1, math.ceil(config.max_concurrency / shards)),
            rate_limit_default_wait_s=config.rate_limit_default_wait_s,
            anchor=config.window_anchor,
        )
        self.leased = LeasedBudget(quota, name, tag)
        super().__init__(
            config,
            run_dir=run_dir,
            run_id=run_id,
            budget=self.leased,
            prices=prices,
            admission=admission,
        )
        self.shard_admission = admission

    async def aclose(self) -> None:
        await super().aclose()  # the last report; the unused lease goes back
        await self.shard_admission.aclose()

    def stats(self) -> dict[str, Any]:
        out = super().stats()
        out["lease_counts"] = dict(self.leased.counts)
        return out
