"""Thin Ray wrappers: one async ``GatewayActor`` per deployment, one budget authority per run
(a ``BudgetActor``, or a ``QuotaActor`` whose gateways spend dollar leases: what a pipeline run
starts, :mod:`pipeline.gateway_backend`).

Why thin: all behaviour lives in :class:`workers.gateway.core.DeploymentGateway` and
:class:`workers.gateway.ledger.BudgetLedger`, tested without Ray. The actors only host them.

Control methods (stats, pause, resume, set_limits, set_caps) run in their own concurrency
group - Ray gives each group its own thread and event loop - so they never queue behind
requests. They are handed to the request loop with ``call_soon_threadsafe`` (asyncio objects
belong to one loop); requests there only await, so a control call waits microseconds.

Requests return an envelope, ``("ok", LLMResponse)`` or ``("error", kind, message, retries,
cost_usd, refusal)`` (``refusal``: the :class:`schemas.outcomes.BudgetRefusal` of a ``budget``
error, else None), which :class:`workers.gateway.client.GatewayClient` turns back into a response or
an ``LLMError`` of the same kind (Ray's own exception wrapping would lose the kind).
"""

from __future__ import annotations

import asyncio
import json
import os
import time
import uuid
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")

import ray  # noqa: E402

from recap.llm import LLMError, LLMRequest  # noqa: E402
from schemas.parts import PartWriter  # noqa: E402
from schemas.records import EventRecord  # noqa: E402
from workers.gateway.call_log import run_id_of  # noqa: E402
from workers.gateway.client import GatewayClient  # noqa: E402
from workers.gateway.ledger import BudgetLedger, EpisodeBudget, LocalBudget  # noqa: E402
from workers.gateway.quota import LeaseLedger, LocalQuota, QuotaBook, lease_s_for, pool_spec  # noqa: E402
from workers.llm.errors import scrub  # noqa: E402
from workers.log_setup import configure_from_env  # noqa: E402

if TYPE_CHECKING:
    # imported by GatewayActor.__init__, not with this module: Ray imports this module wherever a
    # handle to one of its actors is deserialised (every episode worker, the budget actor), and
    # the gateway's core brings litellm's call path, pydantic and pyarrow (issue 37, item 3)
    from workers.gateway.core import DeploymentGateway
    from workers.llm.providers import DeploymentConfig

CONTROL = "control"


class SecretEnv:
    """Environment variables (API keys) handed to a gateway actor as a constructor argument.

    Why not Ray's ``runtime_env``: Ray writes a job's runtime environment, variables included,
    into its session logs (``runtime_env_agent.log``), so a key passed that way ends up on
    disk. Its repr names the variables only, so an error message or log line that shows the
    actor's arguments cannot print a key either."""

    def __init__(self, values: Mapping[str, str] | None = None):
        self._values = dict(values or {})

    def apply(self) -> None:
        os.environ.update(self._values)

    def names(self) -> list[str]:
        return sorted(self._values)

    def __repr__(self) -> str:
        return f"SecretEnv({', '.join(self.names())})"

    __str__ = __repr__


def _ledger_restored_event(run_dir: str, ledger: BudgetLedger) -> None:
    """An ``events`` row when a restarted budget authority found reservations of a dead
    process in the journal (charged at worst case): the restart is visible in the tables."""
    if not ledger.restored_orphans:
        return
    try:
        run_id = run_id_of(run_dir)
    except Exception:  # a bare ledger folder (tests): nothing to attach the row to
        return
    stats = ledger.stats()
    detail = {"orphans": ledger.restored_orphans, "spent_usd": stats["spent_usd"]}
    PartWriter(Path(run_dir), f"budget-{uuid.uuid4().hex[:6]}").write_records(
        run_id,
        [
            EventRecord(
                ts=time.time(),
                source="gateway",
                kind="ledger_restored",
                severity="warning",
                detail=json.dumps(detail, sort_keys=True),
            )
        ],
    )


@ray.remote(num_cpus=0, concurrency_groups={CONTROL: 2})
class BudgetActor(LocalBudget):
    """The run's single budget authority (one journal writer per run folder). The request-path
    methods (begin, reserve, settle, ...) are LocalBudget's; control methods run in their own
    concurrency group so they never wait behind requests."""

    def __init__(
        self,
        run_dir: str,
        run_cap_usd: float | None = None,
        model_caps_usd: Mapping[str, float] | None = None,
        durable_reservations: bool = True,
        group_commit: bool = True,
        provider_models: Mapping[str, str] | None = None,
    ):
        super().__init__(
            BudgetLedger(
                run_dir,
                run_cap_usd=run_cap_usd,
                model_caps_usd=model_caps_usd,
                durable_reservations=durable_reservations,
                provider_models=provider_models,
            ),
            group_commit=group_commit,
        )
        _ledger_restored_event(run_dir, self.ledger)

    @ray.method(concurrency_group=CONTROL)
    async def stats(self) -> dict[str, Any]:  # type: ignore[override]  # async over Ray: callers await the handle
        return self.ledger.stats()

    @ray.method(concurrency_group=CONTROL)
    async def set_caps(self, run_cap_usd: float | None = None, model_caps_usd: Mapping[str, float] | None = None) -> None:
        self.ledger.set_caps(run_cap_usd, model_caps_usd)


class RemoteBudget:
    """The async face of a ``BudgetActor`` handle, as a gateway core expects it."""

    def __init__(self, handle: Any):
        self.handle = handle
        self._unconfirmed: list[Any] = []  # settlements sent without waiting

    async def begin(
        self, call_key: str, name: str, worst_pico: int, cache_key: str | None, owner: str, episode: EpisodeBudget | None = None
    ) -> Any:
        return await self.handle.begin.remote(call_key, name, worst_pico, cache_key, owner, episode)

    async def reserve(self, call_key: str, name: str, worst_pico: int, owner: str, episode: EpisodeBudget | None = None) -> Any:
        return await self.handle.reserve.remote(call_key, name, worst_pico, owner, episode)

    async def settle(
        self, rid: int, cost_pico: int, status: str, result: Any, cache_key: str | None, litellm_cost_usd: float | None
    ) -> None:
        # not awaited: the reservation already bounds this call's cost, so the caller need
        # not wait a round trip; if the settlement is lost, a restart charges the worst case
        self._unconfirmed.append(self.handle.settle.remote(rid, cost_pico, status, result, cache_key, litellm_cost_usd))
        if len(self._unconfirmed) > 256:
            _, self._unconfirmed = ray.wait(self._unconfirmed, num_returns=len(self._unconfirmed), timeout=0)

    async def charge_worst(self, rid: int) -> Any:
        return await self.handle.charge_worst.remote(rid)

    async def adopt_orphans(self, deployment: str, keep_owner: str) -> Any:
        return await self.handle.adopt_orphans.remote(deployment, keep_owner)

    async def stats(self) -> dict[str, Any]:
        return await self.handle.stats.remote()

    async def close(self) -> None:
        """Wait for the settlements sent so far (the BudgetActor outlives any one gateway)."""
        pending, self._unconfirmed = self._unconfirmed, []
        if pending:
            await asyncio.gather(*pending, return_exceptions=True)


@ray.remote(num_cpus=0, concurrency_groups={CONTROL: 2})
class QuotaActor(LocalQuota):
    """The run's budget authority when a deployment runs gateway shards: the ``BudgetActor``'s
    protocol (one journal writer per run folder) plus the shards' window shares and dollar
    leases (:mod:`workers.gateway.quota`). ``configs``: every deployment of the run (the sharded
    ones' RPM/TPM quotas live here); ``shards``: deployment name -> its number of shards;
    ``lease_calls``: worst cases per dollar grant (:class:`workers.gateway.quota.LeaseLedger`);
    ``provider_models``: see :class:`workers.gateway.ledger.BudgetLedger` (default: the configs').
    Also the authority of a pipeline run's unsharded gateways (``GatewayActor(leased=True)``):
    they spend dollar leases too, their RPM/TPM windows stay their own."""

    def __init__(
        self,
        run_dir: str,
        configs: Sequence[DeploymentConfig],
        shards: Mapping[str, int],
        run_cap_usd: float | None = None,
        model_caps_usd: Mapping[str, float] | None = None,
        group_commit: bool = True,
        lease_calls: int = 16,
        provider_models: Mapping[str, str] | None = None,
    ):
        configure_from_env()
        sharded = [c for c in configs if shards.get(c.deployment_name, 1) > 1]
        ledger = LeaseLedger(
            run_dir,
            run_cap_usd=run_cap_usd,
            model_caps_usd=model_caps_usd,
            provider_models=dict(provider_models)
            if provider_models is not None
            else {c.deployment_name: c.model for c in configs},
            shards=dict(shards),
            lease_calls=lease_calls,
        )
        lease_s = min((lease_s_for(c.window_s) for c in sharded), default=10.0)
        book = QuotaBook(pool_spec(sharded), lease_s=lease_s, restarted=ledger.orphaned_leases > 0)
        super().__init__(ledger, book, group_commit=group_commit)
        _ledger_restored_event(run_dir, self.ledger)

    @ray.method(concurrency_group=CONTROL)
    async def stats(self) -> dict[str, Any]:  # type: ignore[override]  # async over Ray: callers await the handle
        return {**self.ledger.stats(), "requests": dict(self.requests), **self.ledger.lease_stats()}

    @ray.method(concurrency_group=CONTROL)
    async def set_caps(self, run_cap_usd: float | None = None, model_caps_usd: Mapping[str, float] | None = None) -> None:
        self.ledger.set_caps(run_cap_usd, model_caps_usd)


class RemoteQuota(RemoteBudget):
    """The async face of a ``QuotaActor`` handle, as a gateway shard expects it."""

    async def report(
        self, lease: int | None, name: str, owner: str, calls: Sequence[tuple], give: int = 0, want_worst: int = 0
    ) -> Any:
        return await self.handle.report.remote(lease, name, owner, list(calls), give, want_worst)

    async def window_lease(self, deployment: str, shard: str, give: tuple[int, int], want: tuple[int, int]) -> Any:
        return await self.handle.window_lease.remote(deployment, shard, give, want)

    async def window_release(self, deployment: str, shard: str) -> None:
        await self.handle.window_release.remote(deployment, shard)

    async def recorded_keys(self) -> Any:
        return await self.handle.recorded_keys.remote()


@ray.remote(num_cpus=0, concurrency_groups={CONTROL: 2})
class GatewayActor:
    """Hosts one :class:`DeploymentGateway`; ``budget`` is the run's ``BudgetActor`` - a handle,
    or the name of a named one - (or None: the gateway keeps its own ledger in the run folder,
    for a single-deployment run). ``secret_env``: API keys set in this actor's process only.
    ``group_commit``: for the own ledger, see :class:`LocalBudget` (False only for benches).
    ``shard``: (index, number of shards) when this actor is one shard of its deployment; then
    ``budget`` is the run's ``QuotaActor`` (:class:`workers.gateway.shard.ShardGateway`).
    ``leased``: the deployment's only gateway, whose ``budget`` is the run's ``QuotaActor``: it
    spends a dollar lease (:class:`workers.gateway.shard.LeasedBudget`, at most ``keep_worst``
    worst cases unused) and reports its calls in batches instead of two round trips per call;
    its RPM/TPM window is its own, as without a lease."""

    def __init__(
        self,
        config: DeploymentConfig | Mapping[str, Any],
        run_dir: str,
        run_id: str | None = None,
        budget: Any = None,
        run_cap_usd: float | None = None,
        model_caps_usd: Mapping[str, float] | None = None,
        secret_env: SecretEnv | None = None,
        group_commit: bool = True,
        shard: tuple[int, int] | None = None,
        leased: bool = False,
        keep_worst: int = 4,
    ):
        configure_from_env()
        if secret_env is not None:  # the API keys, for this actor process only
            secret_env.apply()
        if isinstance(budget, str):  # a named BudgetActor: no handle among the arguments, so Ray
            budget = ray.get_actor(budget)  # restarts this actor without an object-store argument

        from workers.gateway.core import DeploymentGateway
        from workers.gateway.shard import LeasedBudget, ShardGateway
        from workers.llm.providers import DeploymentConfig

        cfg = config if isinstance(config, DeploymentConfig) else DeploymentConfig(**config)
        self.core: DeploymentGateway
        if shard is not None:  # shard (index, of n): its quota and budget are leases from the QuotaActor
            self.core = ShardGateway(
                cfg, index=shard[0], shards=shard[1], quota=RemoteQuota(budget), run_dir=run_dir, run_id=run_id
            )
            return
        if leased:  # the run's QuotaActor grants this gateway dollar leases; the window is its own
            name = cfg.deployment_name
            leased_budget = LeasedBudget(RemoteQuota(budget), name, name, keep_worst=keep_worst)
            self.core = DeploymentGateway(cfg, run_dir=Path(run_dir), run_id=run_id, budget=leased_budget)
            return
        if budget is None:  # the gateway keeps the run's ledger itself
            own = BudgetLedger(
                run_dir, run_cap_usd=run_cap_usd, model_caps_usd=model_caps_usd, provider_models={cfg.deployment_name: cfg.model}
            )
            gate: Any = LocalBudget(own, group_commit=group_commit)
        else:
            gate = RemoteBudget(budget)
        self.core = DeploymentGateway(cfg, run_dir=Path(run_dir), run_id=run_id, budget=gate)

    async def complete(self, request: LLMRequest) -> tuple:
        try:
            return ("ok", await self.core.complete(request))
        except LLMError as exc:
            return ("error", exc.kind, exc.message, exc.retries, exc.cost_usd, exc.refusal)
        except Exception as exc:  # e.g. the budget actor died: transient for the caller
            return ("error", "server_error", scrub(f"gateway failure: {type(exc).__name__}: {exc}")[:500], 0, 0.0, None)

    async def _on_core_loop(self, fn: Callable[[], Any]) -> Any:
        loop = self.core.loop
        if loop is None or not loop.is_running():
            return fn()  # no request has started the core's loop yet: nothing to race with
        done: asyncio.Future = asyncio.get_running_loop().create_future()
        here = asyncio.get_running_loop()

        def run() -> None:
            try:
                value = fn()
            except BaseException as exc:  # hand the failure back to the control loop
                here.call_soon_threadsafe(done.set_exception, exc)
            else:
                here.call_soon_threadsafe(done.set_result, value)

        loop.call_soon_threadsafe(run)
        return await done

    @ray.method(concurrency_group=CONTROL)
    async def stats(self) -> dict[str, Any]:
        return await self._on_core_loop(self.core.stats)

    @ray.method(concurrency_group=CONTROL)
    async def report_spend(self) -> None:
        """Report the calls settled under a dollar lease so far (the authority's spend is then
        exact); nothing to do for a gateway that settles each call at the authority."""
        report = getattr(self.core.budget, "report_now", None)
        loop = self.core.loop
        if report is None or loop is None or not loop.is_running():
            return
        await asyncio.wrap_future(asyncio.run_coroutine_threadsafe(report(), loop))

    @ray.method(concurrency_group=CONTROL)
    async def budget_stats(self) -> dict[str, Any]:
        return await self.core.budget.stats()

    @ray.method(concurrency_group=CONTROL)
    async def pause(self) -> None:
        await self._on_core_loop(self.core.pause)

    @ray.method(concurrency_group=CONTROL)
    async def resume(self) -> None:
        await self._on_core_loop(self.core.resume)

    @ray.method(concurrency_group=CONTROL)
    async def set_limits(self, rpm: int | None = None, tpm: int | None = None, max_concurrency: int | None = None) -> None:
        await self._on_core_loop(lambda: self.core.set_limits(rpm=rpm, tpm=tpm, max_concurrency=max_concurrency))

    async def close(self) -> None:
        await self.core.aclose()


class RunGateways:
    """The gateways of one run: one GatewayActor per deployment and one budget authority.

    ``budget``: ``"shared"`` - a BudgetActor serves every deployment (needed when a run has
    several deployments: caps are per run); ``"local"`` - the single deployment's
    GatewayActor keeps the ledger itself (no extra round trips per call); ``"auto"`` (default)
    - local for one deployment, shared otherwise; or an existing BudgetActor handle.
    ``shards``: gateway shards per deployment (an int for all, or name -> int; default 1). A
    deployment with more than one runs that many GatewayActors, sharing its quota and the caps
    through leases from a ``QuotaActor``, which then is the run's budget authority in place of the
    BudgetActor (:mod:`workers.gateway.quota`); with 1 everywhere nothing changes.
    ``client(name, worker=i)`` gives the :class:`GatewayClient` of a deployment (by deployment
    name or model, when the model has one deployment); worker ``i`` gets shard ``i % shards``
    (round robin; without ``worker``, successive clients take the shards in turn).
    ``model_caps_usd`` is keyed by deployment name, as the ledger keeps spend. ``group_commit``:
    see :class:`LocalBudget` (False only for the bench's before figures).
    """

    def __init__(
        self,
        configs: Sequence[DeploymentConfig],
        run_dir: Path | str,
        run_id: str,
        run_cap_usd: float | None = None,
        model_caps_usd: Mapping[str, float] | None = None,
        budget: Any = "auto",
        group_commit: bool = True,
        shards: int | Mapping[str, int] = 1,
    ):
        self.run_dir = str(run_dir)
        self.run_id = run_id
        self.configs = list(configs)
        names = [c.deployment_name for c in self.configs]
        if len(set(names)) != len(names):
            raise ValueError(f"two deployments share a name: {sorted(names)}")
        self.n_shards = {n: (shards if isinstance(shards, int) else int(shards.get(n, 1))) for n in names}
        if any(k < 1 for k in self.n_shards.values()):
            raise ValueError(f"gateway shards must be at least 1: {self.n_shards}")
        self._turn = 0
        self.shards: dict[str, list[Any]] = {}
        if any(k > 1 for k in self.n_shards.values()):
            if budget not in ("auto", "shared"):
                raise ValueError("gateway shards need the run's QuotaActor as the budget (budget='auto' or 'shared')")
            self.budget = QuotaActor.remote(
                self.run_dir, self.configs, self.n_shards, run_cap_usd, model_caps_usd, group_commit=group_commit
            )
            for c in self.configs:
                n = self.n_shards[c.deployment_name]
                self.shards[c.deployment_name] = [
                    GatewayActor.remote(c, self.run_dir, run_id, self.budget, shard=(k, n) if n > 1 else None) for k in range(n)
                ]
            self.actors = {name: group[0] for name, group in self.shards.items()}
            return
        if budget == "auto":
            budget = "local" if len(self.configs) == 1 else "shared"
        if budget == "local":
            if len(self.configs) != 1:
                raise ValueError("budget='local' needs exactly one deployment (caps are per run)")
            self.budget = None
            self.actors = {
                names[0]: GatewayActor.remote(
                    self.configs[0], self.run_dir, run_id, None, run_cap_usd, model_caps_usd, group_commit=group_commit
                )
            }
        else:
            providers = {c.deployment_name: c.model for c in self.configs}
            self.budget = (
                BudgetActor.remote(
                    self.run_dir, run_cap_usd, model_caps_usd, group_commit=group_commit, provider_models=providers
                )
                if budget == "shared"
                else budget
            )
            self.actors = {c.deployment_name: GatewayActor.remote(c, self.run_dir, run_id, self.budget) for c in self.configs}
        self.shards = {name: [a] for name, a in self.actors.items()}

    def _name(self, name: str) -> str:
        if name in self.actors:
            return name
        matches = [c.deployment_name for c in self.configs if c.model == name]
        if len(matches) != 1:
            raise KeyError(f"no single deployment named or serving {name!r}; deployments: {sorted(self.actors)}")
        return matches[0]

    def client(self, name: str, worker: int | None = None) -> Any:
        dep = self._name(name)
        group = self.shards[dep]
        if worker is None:
            worker, self._turn = self._turn, self._turn + 1
        return GatewayClient(group[worker % len(group)], deployment=dep)

    def stats(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for name, group in self.shards.items():
            per = ray.get([a.stats.remote() for a in group])
            out[name] = per[0] if len(per) == 1 else merged_shard_stats(per)
        if self.budget is not None:
            out["budget"] = ray.get(self.budget.stats.remote())
        else:
            out["budget"] = ray.get(next(iter(self.actors.values())).budget_stats.remote())
        return out

    def budget_stats(self) -> dict[str, Any]:
        return self.stats()["budget"]

    def close(self) -> None:
        """Flush every gateway's rows and close the ledger journal."""
        ray.get([a.close.remote() for group in self.shards.values() for a in group])
        if self.budget is not None:
            ray.get(self.budget.close.remote())


def merged_shard_stats(per: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """One deployment's figures over its shards: the counters summed, the quota (``rpm``,
    ``tpm``: the deployment's) as any shard reports it, each shard's own figures under ``shards``."""
    out: dict[str, Any] = dict(per[0])
    for key in ("window_requests", "window_tokens", "inflight", "active", "waiting", "rows_written", "rows_pending", "spent_usd"):
        out[key] = sum(p.get(key) or 0 for p in per)
    paused = [p["paused_until"] for p in per if p.get("paused_until")]
    out["paused_until"] = max(paused) if paused else None
    calls: dict[str, int] = {}
    for p in per:
        for k, v in p.get("calls", {}).items():
            calls[k] = calls.get(k, 0) + v
    out["calls"] = calls
    out["shards"] = list(per)
    return out
