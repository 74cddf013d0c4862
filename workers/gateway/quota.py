"""The quota authority of a sharded deployment: one holder of each model's RPM/TPM quota and of the dollar caps.

Why: one gateway actor per deployment saturates a core long before a 10K-RPM quota does, so a
deployment can run N gateway *shards*. They must still share one quota and one set of caps, and
a round trip to a central actor per call is what sharding is meant to avoid. So each shard holds
*leases* taken from this authority and spends them locally (:mod:`workers.gateway.shard`).

Window shares (:class:`QuotaBook`). The deployment's quota ``Q`` (requests or tokens per
window) is split into shares: a shard admits a request only while its own sliding window
(:class:`workers.gateway.limits.SlidingWindow`, same entries and same anchoring as a single
gateway) stays within its share. At every instant the shares granted plus the shares waiting to
drain sum to at most ``Q``, and every shard's window holds at most its share, so the union of the
shards' windows - which covers any provider-side window exactly as one gateway's would - holds at
most ``Q``. A shard gives share back only out of its slack (share minus what its window holds now)
and lowers its own limit before telling the authority, so given-back share is free at once. A
share is granted for ``lease_s``; a shard renews it well before. A shard that stops renewing (it
died, or lost the authority) stops admitting at its own expiry, and its share *drains*: it
becomes free ``drain_s`` after the authority's expiry (the window span, plus the longest attempt,
plus a margin), when every request it admitted has left every window. A live shard whose renewal
merely came late takes its draining share back (it admitted nothing meanwhile); shard names are
per incarnation, so a restarted shard never takes its dead predecessor's. A shard that closes
hands its share back to drain for one window span.

Dollar leases (:class:`LeaseLedger`). A lease is a reservation in the run's ledger journal, owned
by the shard (``<deployment>#s<k>:<instance>``), for a slice of the headroom under the run cap and
the model's cap. The shard reserves each call's worst case out of its lease and settles it
locally; every ``report`` writes the calls it settled into the journal (their results serve
idempotency, their cost becomes spend) and replaces the lease by what is left, minus what the
shard gives back, plus what it asks for. The lease stays reserved in the ledger at its full
remaining amount until reported, so committed spend (spent + reserved, leases included) never
passes a cap. A dead shard's lease is an open reservation: the next incarnation of the shard
(``adopt_orphans``) or a restarted ledger charges it at its full amount - as the worst case of
whatever the shard may have spent under it. Grants shrink with the headroom
(``headroom / (4 x shards)``, at most ``lease_calls`` worst cases); below one worst case the shard
reserves call by call through the authority, as a single gateway does.

Ray-free: the ``QuotaActor`` (:mod:`workers.gateway.actors`) only hosts :class:`LocalQuota`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from workers.gateway.entries import NAME_FIELD
from workers.gateway.ledger import BudgetLedger, LocalBudget

#: a lease's key prefix in the ledger journal (a reservation that is no call)
LEASE_KEY = "lease:"

#: one call settled inside a lease, as a shard reports it:
#: (call_key, cost pico, status, result or None, cache_key or None, provider cost USD or None)
LeasedCall = tuple[str, int, str, Any, Any, Any]


#: the owner of a draining share nobody may take back (a closed shard, a dead authority's grants)
_CLOSED_TAG = "closed:"


@dataclass
class _Share:
    """What one shard holds of one deployment's quota."""

    requests: int = 0
    tokens: int = 0
    expires: float = 0.0


@dataclass
class _Pool:
    """One deployment's quota: the limits, the shards' shares, and the shares still draining."""

    rpm: int | None
    tpm: int | None
    span_s: float
    drain_s: float
    shards: dict[str, _Share] = field(default_factory=dict)
    #: (free at, requests, tokens, shard): shares of shards that lapsed or closed
    draining: list[tuple[float, int, int, str]] = field(default_factory=list)

    def held(self) -> tuple[int, int]:
        req = sum(s.requests for s in self.shards.values()) + sum(d[1] for d in self.draining)
        tok = sum(s.tokens for s in self.shards.values()) + sum(d[2] for d in self.draining)
        return req, tok


class QuotaBook:
    """The RPM/TPM shares of every sharded deployment (see the module docstring).

    ``deployments``: name -> (rpm, tpm, window span in seconds, drain seconds after a lapsed
    lease). ``lease_s``: how long a grant is valid without a renewal. ``restarted``: an earlier
    authority of this run died holding leases (the ledger found them open): the shares it had
    granted are unknown, so the whole quota drains as a lapsed share would before any grant."""

    def __init__(
        self,
        deployments: Mapping[str, tuple[int | None, int | None, float, float]],
        *,
        lease_s: float = 10.0,
        clock: Callable[[], float] = time.monotonic,
        restarted: bool = False,
    ):
        self.lease_s = lease_s
        self._clock = clock
        self.pools = {name: _Pool(rpm, tpm, span, drain) for name, (rpm, tpm, span, drain) in deployments.items()}
        if restarted:  # an earlier authority died with shares out: all of them may still be in use
            now = clock()
            for pool in self.pools.values():
                pool.draining.append((now + lease_s + pool.drain_s, pool.rpm or 0, pool.tpm or 0, _CLOSED_TAG))

    def _expire(self, pool: _Pool, now: float) -> None:
        for shard, share in list(pool.shards.items()):
            if share.expires < now:  # lapsed: the shard admits nothing more under it
                del pool.shards[shard]
                pool.draining.append((share.expires + pool.drain_s, share.requests, share.tokens, shard))
        pool.draining = [d for d in pool.draining if d[0] > now]

    def lease(self, deployment: str, shard: str, give: tuple[int, int], want: tuple[int, int]) -> dict[str, Any]:
        """Renew ``shard``'s share: take back ``give`` (requests, tokens) - slack the shard has
        already removed from its own limit - and grant up to ``want`` more out of what is free.
        Returns the shard's whole share and how long it is valid. A shard whose lease lapsed takes
        back its share while it drains (``shard`` names one incarnation), else starts from nothing."""
        pool = self.pools[deployment]
        now = self._clock()
        self._expire(pool, now)
        share = pool.shards.get(shard)
        if share is None:
            share = pool.shards[shard] = _Share()
            # a live shard whose lease lapsed (a renewal came late): it admitted nothing since,
            # and its window never held more than that share, so the share is its own again
            mine = [d for d in pool.draining if d[3] == shard]
            if mine:
                pool.draining = [d for d in pool.draining if d[3] != shard]
                share.requests = sum(d[1] for d in mine)
                share.tokens = sum(d[2] for d in mine)
        share.requests -= min(max(0, give[0]), share.requests)
        share.tokens -= min(max(0, give[1]), share.tokens)
        held_req, held_tok = pool.held()
        if pool.rpm is not None:
            share.requests += max(0, min(want[0], pool.rpm - held_req))
        if pool.tpm is not None:
            share.tokens += max(0, min(want[1], pool.tpm - held_tok))
        share.expires = now + self.lease_s
        return {"requests": share.requests, "tokens": share.tokens, "valid_s": self.lease_s}

    def release(self, deployment: str, shard: str) -> None:
        """A closing shard: its share drains for one window span (its last entries' lifetime)."""
        pool = self.pools[deployment]
        share = pool.shards.pop(shard, None)
        if share is not None:
            pool.draining.append((self._clock() + pool.span_s, share.requests, share.tokens, _CLOSED_TAG + shard))

    def stats(self, deployment: str) -> dict[str, Any]:
        pool = self.pools[deployment]
        self._expire(pool, self._clock())
        held_req, held_tok = pool.held()
        return {
            "rpm": pool.rpm,
            "tpm": pool.tpm,
            "shards": {k: (s.requests, s.tokens) for k, s in sorted(pool.shards.items())},
            "held_requests": held_req,
            "held_tokens": held_tok,
            "draining": len(pool.draining),
        }


class LeaseLedger(BudgetLedger):
    """A :class:`BudgetLedger` that also grants dollar leases to gateway shards (see the module
    docstring). Leases and the calls reported in them are ordinary ``reserve`` / ``settle``
    journal entries, so a journal with leases replays with the plain ledger too."""

    #: leases a dead authority left open, charged in full when this one replayed the journal
    orphaned_leases = 0

    def _write_settle(self, rid: int, pico: int, status: str, **extra: Any) -> None:
        if status == "orphaned" and self.open[rid][0].startswith(LEASE_KEY):
            self.orphaned_leases += 1
        super()._write_settle(rid, pico, status, **extra)

    def __init__(self, *args: Any, shards: int | Mapping[str, int] = 1, lease_calls: int = 16, **kwargs: Any):
        super().__init__(*args, **kwargs)
        #: shards per deployment (an int: every deployment), which sizes each one's leases
        self.shards = shards
        self.lease_calls = lease_calls
        self.leases_granted = 0
        self.leases_short = 0
        self.settled_in_leases = 0

    def _headroom(self, name: str) -> int | None:
        """Pico-USD that may still be committed for ``name`` (None: no cap applies)."""
        room: list[int] = []
        if self.run_cap is not None:
            room.append(self.run_cap - self.spent - self.reserved)
        cap = self.model_caps.get(name)
        if cap is not None:
            room.append(cap - self.spent_by_model[name] - self.reserved_by_model[name])
        return min(room) if room else None

    def _grant(self, name: str, worst: int) -> int:
        """A lease for calls whose worst case is about ``worst``: ``lease_calls`` of them, or a
        share of the headroom that shrinks with it; 0 when that is below one worst case."""
        want = max(1, worst) * self.lease_calls
        room = self._headroom(name)
        if room is None:
            return want
        n = self.shards if isinstance(self.shards, int) else self.shards.get(name, 1)
        grant = min(want, room // (4 * max(1, n)))
        return grant if grant >= worst and grant > 0 else 0

    def _new_lease(self, name: str, owner: str, pico: int) -> int:
        rid = self._next_rid
        self._next_rid += 1
        key = f"{LEASE_KEY}{rid}"  # no '#': a lease names no episode (workers.gateway.entries.episode_of)
        self._journal.append(
            {"op": "reserve", "rid": rid, "key": key, NAME_FIELD: name, "pico": pico, "owner": owner, "t": time.time()},
            sync=self.durable_reservations,
        )
        self._open(rid, key, name, pico, owner)
        return rid

    def report(
        self,
        lease: int | None,
        name: str,
        owner: str,
        calls: Sequence[LeasedCall],
        give: int = 0,
        want_worst: int = 0,
    ) -> dict[str, Any]:
        """Write the calls a shard settled under ``lease``, shrink the lease by their cost and
        ``give``, and grow it by a grant sized for calls of ``want_worst`` (0: no more wanted).

        Returns ``{"lease": rid or None, "pico": its amount}``: the shard's lease from now on.
        A lease that is no longer open was charged in full when the ledger restarted (its calls
        are recorded at 0 - their cost is inside that charge) and the shard starts a new one."""
        with self._lock:
            live = lease is not None and lease in self.open
            for key, cost, status, result, cache_key, provider_cost in calls:
                self._write_call(key, name, owner, int(cost) if live else 0, status, result, cache_key, provider_cost, lease)
            left = 0
            if live:
                assert lease is not None
                spent_in = sum(int(c[1]) for c in calls)
                left = max(0, self.open[lease][2] - spent_in - max(0, int(give)))
            self.settled_in_leases += len(calls)
            grant = self._grant(name, want_worst) if want_worst > 0 else 0
            if not live and grant == 0:
                if calls:
                    self._journal.sync()
                return {"lease": None, "pico": 0, "lost": lease is not None}
            if grant == 0 and want_worst > 0:
                self.leases_short += 1
            elif grant:
                self.leases_granted += 1
            # the new lease is written before the old one is closed: a crash in between charges both
            new = self._new_lease(name, owner, left + grant) if left + grant > 0 else None
            if live:
                assert lease is not None
                self._write_settle(lease, 0, "lease_renewed")
            self._journal.sync()
            return {"lease": new, "pico": left + grant if new is not None else 0, "lost": lease is not None and not live}

    def _write_call(
        self,
        key: str,
        name: str,
        owner: str,
        cost: int,
        status: str,
        result: Any,
        cache_key: Any,
        provider_cost: Any,
        lease: int | None,
    ) -> None:
        """One call settled inside a lease: a reservation at its cost (covered by the lease, so
        no cap check) and its settlement, with the result for idempotency and the cache."""
        rid = self._next_rid
        self._next_rid += 1
        self._journal.append(
            {"op": "reserve", "rid": rid, "key": key, NAME_FIELD: name, "pico": cost, "owner": owner, "lease": lease}
        )
        self._open(rid, key, name, cost, owner)
        extra: dict[str, Any] = {}
        if result is not None:
            extra["result"] = dict(result)
        if cache_key is not None:
            extra["cache_key"] = cache_key
        if provider_cost is not None:
            extra["litellm_cost_usd"] = provider_cost
        self._write_settle(rid, cost, status, **extra)

    def recorded_keys(self) -> list[str]:
        """The call keys with a recorded result (a starting shard asks for these only)."""
        with self._lock:
            return list(self.results)

    def lease_stats(self) -> dict[str, Any]:
        with self._lock:
            open_leases = [p for (k, _n, p, _o) in self.open.values() if k.startswith(LEASE_KEY)]
            return {
                "open_leases": len(open_leases),
                "leased_usd": sum(open_leases) / 1e12,
                "leases_granted": self.leases_granted,
                "leases_short": self.leases_short,
                "settled_in_leases": self.settled_in_leases,
            }


def drain_s(span_s: float, attempt_timeout_s: float, margin_s: float = 10.0) -> float:
    """How long after its lapse a shard's share still counts: every request it admitted before
    the lapse has been answered (one attempt's time, plus a margin for the budget round trip)
    and has left every window (one span)."""
    return span_s + attempt_timeout_s + margin_s


def lease_s_for(window_s: float) -> float:
    """A grant's validity (renewed three times per validity): half the window, between 5 and
    30 s. Long enough that a renewal delayed by a busy machine does not lapse the share (a lapsed
    share drains for a whole ``drain_s``); it only bounds how long a dead shard's share is held."""
    return min(30.0, max(5.0, window_s / 2))


class LocalQuota(LocalBudget):
    """The async face of the quota authority in-process (tests, and what the ``QuotaActor``
    hosts): the budget protocol of :class:`LocalBudget` plus the shard leases."""

    def __init__(self, ledger: LeaseLedger, book: QuotaBook, *, owned: bool = True, group_commit: bool = True):
        super().__init__(ledger, owned=owned, group_commit=group_commit)
        self.ledger: LeaseLedger = ledger
        self.book = book
        #: request-path calls served, by method: what the gateways cost this authority (a
        #: gateway that spends a lease makes ``report``s, not a ``begin`` and a ``settle`` per call)
        self.requests: dict[str, int] = dict.fromkeys(("begin", "reserve", "settle", "charge_worst", "report"), 0)

    async def begin(self, *args: Any, **kwargs: Any) -> Mapping[str, Any]:
        self.requests["begin"] += 1
        return await super().begin(*args, **kwargs)

    async def reserve(self, *args: Any, **kwargs: Any) -> Mapping[str, Any]:
        self.requests["reserve"] += 1
        return await super().reserve(*args, **kwargs)

    async def settle(self, *args: Any, **kwargs: Any) -> None:
        self.requests["settle"] += 1
        await super().settle(*args, **kwargs)

    async def charge_worst(self, rid: int) -> int:
        self.requests["charge_worst"] += 1
        return await super().charge_worst(rid)

    async def report(
        self, lease: int | None, name: str, owner: str, calls: Sequence[LeasedCall], give: int = 0, want_worst: int = 0
    ) -> dict[str, Any]:
        self.requests["report"] += 1
        return self.ledger.report(lease, name, owner, calls, give, want_worst)

    async def window_lease(self, deployment: str, shard: str, give: tuple[int, int], want: tuple[int, int]) -> dict[str, Any]:
        return self.book.lease(deployment, shard, give, want)

    async def window_release(self, deployment: str, shard: str) -> None:
        self.book.release(deployment, shard)

    async def recorded_keys(self) -> list[str]:
        return self.ledger.recorded_keys()

    async def quota_stats(self, deployment: str) -> dict[str, Any]:
        return {**self.book.stats(deployment), **self.ledger.lease_stats()}


def pool_spec(configs: Iterable[Any]) -> dict[str, tuple[int | None, int | None, float, float]]:
    """QuotaBook deployments from :class:`workers.llm.providers.DeploymentConfig` objects."""
    out = {}
    for c in configs:
        span = c.window_s + c.window_pad_s
        out[c.deployment_name] = (c.rpm, c.tpm, span, drain_s(span, c.attempt_timeout_s))
    return out


def fair_share(limit: int | None, shards: int) -> int:
    """A shard's first ask: an equal part of the quota (0 without a quota)."""
    return 0 if limit is None else max(1, limit // max(1, shards))


def chunk(limit: int | None, shards: int) -> int:
    """What a shard short of room asks for at a time."""
    return 0 if limit is None else max(1, math.ceil(limit / (4 * max(1, shards))))
