"""The product's model backend: the LLM gateway (``workers.gateway``) on Ray.

One budget authority per run, a ``QuotaActor`` (the dollar caps, journalled under
``RUN_DIR/gateway/``), and one ``GatewayActor`` per model of the sweep (rate limits, retries,
the ``llm_calls`` rows). Both write into the run folder, so they are pinned to the driver's
node. Every gateway spends a dollar lease from the authority and reports its settled calls in
batches (:class:`workers.gateway.shard.LeasedBudget`): no model call pays a round trip to the
authority in the normal case (before: a ``begin`` awaited and a ``settle`` sent per call, about
4 ms of the budget process's CPU per call at 32 workers). At most ``LEASE_KEEP_WORST`` worst
cases of a lease lie unused, so a killed gateway (its open lease charged in full by the
restart) is charged at most that much beyond its calls in flight. A model with
``gateway_shards: N`` gets N gateway actors, and the authority also leases each shard its part
of the model's rpm/tpm quota (:mod:`workers.gateway.quota`); episode workers take the shards
round robin. Each sweep model entry
becomes a :class:`workers.llm.providers.DeploymentConfig` (:data:`pipeline.spec.DEPLOYMENT_FIELDS`,
the one mapping); building those configs validates params and test-double options, so a bad
entry fails before anything is written.

One key: a model's deployment is named after the model's name in the sweep
(:attr:`pipeline.spec.ModelSpec.name`), and caps, spend and the ledger journal are kept by that
name, so two entries on one model string (two option sets of a test double, one model behind
two base URLs) never share a cap or a spend figure.
"""

from __future__ import annotations

import logging
import os
import uuid
from typing import Any

from pipeline.backend import RateStats, Spend
from pipeline.deployments import deployment_config
from pipeline.errors import PipelineError
from pipeline.preflight import key_variables
from pipeline.raysetup import actor_runtime_env
from pipeline.spec import SweepSpec
from workers.episode_worker import ClientTable

log = logging.getLogger(__name__)

#: times a call in flight on a gateway (or budget) actor that died is re-sent to its restart;
#: bounded so that a request that kills the actor every time cannot loop for ever
TASK_RETRIES = 3

#: worst cases per dollar grant to a gateway (:class:`workers.gateway.quota.LeaseLedger`)
LEASE_CALLS = 4
#: worst cases a single gateway's lease keeps unused beyond its calls in flight
LEASE_KEEP_WORST = 4


def model_caps(spec: SweepSpec) -> dict[str, float]:
    """Per-model caps keyed by the model's name in the sweep (the gateway ledger's key)."""
    return {m.name: m.cap_usd for m in spec.models if m.cap_usd is not None}


def provider_models(spec: SweepSpec) -> dict[str, str]:
    """Model name -> provider model string, for the ledger to read a journal written before
    spend was kept by name (:class:`workers.gateway.entries.KeyMap`)."""
    return {m.name: m.model for m in spec.models}


#: the factory the workers get: one GatewayClient (an actor handle) per sweep model label, a list of them for a model with gateway shards; defined
#: in the worker's own module, so a worker unpickling it imports nothing of the pipeline
GatewayFactory = ClientTable


class GatewayBackend:
    """The product's :class:`pipeline.backend.ModelBackend`: starts the budget actor and one gateway
    actor per sweep model on the driver's node, and reads spend and rate use from them."""

    writes_llm_calls = True

    def __init__(self, spec: SweepSpec) -> None:
        self.spec = spec
        self.configs = {m.name: deployment_config(m, f"models[{i}]") for i, m in enumerate(spec.models)}
        self.caps = model_caps(spec)
        self.budget: Any = None
        #: gateway shards per model label (``models[].gateway_shards``, default 1)
        self.shards = {m.name: m.gateway_shards or 1 for m in spec.models}
        self.actors: dict[str, Any] = {}  # label -> its (first) gateway actor
        self.shard_actors: dict[str, list[Any]] = {}  # label -> every shard's actor
        self.clients: dict[str, Any] = {}
        self._closed = False

    def serve_at(self, updates: dict[str, dict[str, Any]]) -> None:
        """Point the served models' deployments at their Serve routes (``api_base``) with their
        replicas' share of calls (``max_concurrency``): :mod:`pipeline.serving.service`."""
        for label, fields in updates.items():
            self.configs[label] = self.configs[label].model_copy(update=fields)

    def start(self, *, run_dir: str, run_id: str, runtime_env: dict[str, Any] | None = None, node_id: str | None = None) -> None:
        from workers.gateway import GatewayActor, GatewayClient, QuotaActor  # lazy: the actors module loads Ray

        # a killed gateway or budget actor is restarted by Ray (same arguments: the ledger is
        # replayed from the run folder's journal) and the calls it had in flight are sent to
        # the new incarnation, so a crash of either costs a few seconds, not the episodes
        opts: dict[str, Any] = {"max_restarts": -1, "max_task_retries": TASK_RETRIES}
        env = self._runtime_env()
        if env is not None:
            opts["runtime_env"] = env
        if node_id is not None:
            # lazy: Ray loads only where a session uses it
            from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

            opts["scheduling_strategy"] = NodeAffinitySchedulingStrategy(node_id=node_id, soft=False)
        # named, so that the gateways find it by name: a handle among an actor's arguments makes
        # Ray warn at every start that a restart depends on the object store
        budget_name = f"recap-budget-{run_id}-{uuid.uuid4().hex[:8]}"
        # the authority leases every gateway a slice of the caps (and each shard its rpm/tpm share)
        self.budget = QuotaActor.options(name=budget_name, **opts).remote(
            str(run_dir),
            list(self.configs.values()),
            self.shards,
            self.spec.run_cap_usd,
            self.caps,
            lease_calls=LEASE_CALLS,
            provider_models=provider_models(self.spec),
        )
        keys = self._api_keys()
        for label, cfg in self.configs.items():
            n = self.shards[label]
            group = [
                GatewayActor.options(**opts).remote(
                    cfg,
                    str(run_dir),
                    run_id,
                    budget_name,
                    secret_env=keys,
                    shard=(k, n) if n > 1 else None,
                    leased=n == 1,
                    keep_worst=LEASE_KEEP_WORST,
                )
                for k in range(n)
            ]
            self.actors[label] = group[0]
            self.shard_actors[label] = group
            clients = [GatewayClient(a, deployment=cfg.deployment_name) for a in group]
            self.clients[label] = clients if n > 1 else clients[0]

    def _runtime_env(self) -> dict[str, Any] | None:
        """The job's environment (data folders, offline litellm) for the gateway actors (None: the
        local cluster's workers have it already, :func:`pipeline.raysetup.actor_runtime_env`)."""
        return actor_runtime_env()

    def _api_keys(self) -> Any:
        """The API keys the sweep's models need, read from the driver's environment.

        On a cluster joined with ``--address`` the actors do not inherit the driver's
        environment, so the keys travel with the gateway actors (and only with them: episode
        workers never see a key) - as a constructor argument, never in the ``runtime_env``,
        which Ray writes into its session logs."""

        from workers.gateway.actors import SecretEnv  # lazy: the actors module loads Ray

        keys: dict[str, str] = {}
        for m in self.spec.models:
            for name in key_variables(m):
                if os.environ.get(name):
                    keys[name] = os.environ[name]
        return SecretEnv(keys)

    def factory(self) -> GatewayFactory:
        return GatewayFactory(dict(self.clients))

    def spend(self) -> Spend:
        import ray  # lazy: Ray loads only where a session uses it

        # the calls the gateways settled under their leases since their last report, reported
        # first; a gateway that does not answer soon (a restart under way) is not waited for
        reports = [a.report_spend.remote() for group in self.shard_actors.values() for a in group]
        if reports and not self._closed:
            ray.wait(reports, num_returns=len(reports), timeout=2.0)
        stats = ray.get(self.budget.stats.remote())
        by_model = stats.get("by_model_spent_usd", {})
        return Spend(float(stats.get("spent_usd", 0.0)), {label: float(by_model.get(label, 0.0)) for label in self.configs})

    def rate_stats(self) -> dict[str, RateStats]:
        import ray  # lazy: Ray loads only where a session uses it

        from workers.gateway.actors import merged_shard_stats  # lazy: the actors module loads Ray

        out: dict[str, RateStats] = {}
        groups = {label: self.shard_actors.get(label, [a]) for label, a in self.actors.items()}
        flat = ray.get([a.stats.remote() for group in groups.values() for a in group], timeout=5)
        stats = []
        for group in groups.values():
            per, flat = flat[: len(group)], flat[len(group) :]
            stats.append(per[0] if len(per) == 1 else merged_shard_stats(per))
        for (label, cfg), s in zip(self.configs.items(), stats):
            per_min = 60.0 / cfg.window_s
            out[label] = RateStats(
                rpm=s.get("window_requests", 0) * per_min,
                rpm_limit=(s["rpm"] * per_min) if s.get("rpm") else None,
                tpm=s.get("window_tokens", 0) * per_min,
                tpm_limit=(s["tpm"] * per_min) if s.get("tpm") else None,
                in_flight=s.get("inflight"),
                paused_until=s.get("paused_until"),
            )
        return out

    def set_run_cap(self, usd: float | None) -> None:
        import ray  # lazy: Ray loads only where a session uses it

        if usd is not None:
            ray.get(self.budget.set_caps.remote(usd, None))

    def flush(self) -> None:
        """Write every pending llm_calls row and close the ledger journal (end of session)."""
        import ray  # lazy: Ray loads only where a session uses it

        if self._closed or self.budget is None:
            return
        self._closed = True
        # each gateway on its own: one that fails to close must not keep the others' rows unwritten
        closing = {
            f"{label} (shard {k})" if len(group) > 1 else label: a.close.remote()
            for label, group in self.shard_actors.items()
            for k, a in enumerate(group)
        }
        failed: list[str] = []
        for label, ref in closing.items():
            try:
                ray.get(ref)
            except Exception as exc:
                log.warning("the gateway of %s could not write its last llm_calls rows: %s: %s", label, type(exc).__name__, exc)
                failed.append(label)
        ray.get(self.budget.close.remote())
        if failed:
            raise PipelineError(f"the gateways of {', '.join(failed)} failed to close (their last llm_calls rows may be missing)")

    def close(self) -> None:
        import ray  # lazy: Ray loads only where a session uses it

        try:
            self.flush()
        except Exception as exc:  # closing goes on (the actors are killed below); the cause is logged
            log.warning("closing the model gateways: %s: %s", type(exc).__name__, exc)
        every = [a for group in self.shard_actors.values() for a in group]
        for a in every + ([self.budget] if self.budget is not None else []):
            try:
                ray.kill(a)
            except Exception:
                pass


def make_backend(spec: SweepSpec) -> GatewayBackend:
    """The backend ``recap run`` uses for ``spec`` (the one place the CLI names the gateway)."""
    return GatewayBackend(spec)
