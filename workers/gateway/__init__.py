"""The LLM gateway: every model call of a run, through one place per provider deployment.

Public API
==========

Configuration (built by the pipeline from the sweep spec)::

    DeploymentConfig(model="openai/gpt-4o", api_base=None, api_key_env="OPENAI_API_KEY",
                     rpm=500, tpm=30_000, window_s=60, max_concurrency=16,
                     max_attempts=6, total_timeout_s=900, attempt_timeout_s=120,
                     params={"temperature": 0.5, "max_tokens": 1024},
                     price=None,            # or {"input": 2.5, "cached_input": 1.25, "output": 10}
                     cache=False,           # serve identical requests from the ledger
                     offline_options={})    # offline/ test doubles: noise_seed, invalid_action_rate, ...
    require_prices(models, overrides)      # PriceError naming every model without a price

On Ray (one GatewayActor per deployment; one BudgetActor per run, or - budget="local", the
default for a single deployment - the ledger inside the one GatewayActor; with shards=N, N
GatewayActors per deployment and a QuotaActor in place of the BudgetActor, see
:mod:`workers.gateway.quota`)::

    gws = RunGateways(configs, run_dir, run_id, run_cap_usd=50.0, model_caps_usd={"openai/gpt-4o": 40},
                      budget="auto")           # "shared" | "local" | "auto" | a BudgetActor handle
    # caps and spend are kept by deployment name (DeploymentConfig.deployment_name: its ``name``,
    # else model[@api_base][#key_env]), never by a model string two deployments may share
    # or by hand: BudgetActor.remote(run_dir, run_cap_usd, model_caps_usd, provider_models=...)
    #             GatewayActor.remote(config, run_dir, run_id, budget_actor)
    # RunGateways(..., shards=4): four gateway shards per deployment sharing its quota and the caps
    client = gws.client("openai/gpt-4o")   # GatewayClient, a recap.llm.LLMClient (picklable)
    client = gws.client("openai/gpt-4o", worker=3)   # with shards: worker i -> shard i % N
    resp = client.complete(request)        # LLMResponse, or raises LLMError(kind)
    client.stats(); client.pause(); client.resume(); client.set_limits(rpm=..., tpm=..., max_concurrency=...)
    gws.stats(); gws.close()               # close flushes llm_calls rows and the journal

Without Ray (tests, single process)::

    gw = DeploymentGateway(config, run_dir=run_dir, run_id=run_id, run_cap_usd=5.0)
    resp = await gw.complete(request); await gw.aclose()
    with BlockingGateway(config, run_dir=run_dir, run_id=run_id) as client:   # a sync LLMClient
        resp = client.complete(request)
    # several deployments sharing one budget in-process: budget=LocalBudget(BudgetLedger(run_dir, ...), owned=False)

Without a gateway at all: ``workers.llm.direct.LiteLLMClient(config)`` (same errors and prices,
no quotas, budget or ledger).

Guarantees
==========
- RPM/TPM: no window of ``window_s`` (plus ``window_pad_s`` of jitter) holds more than the limit;
  HTTP 429 halves concurrency and pauses for Retry-After (``stats()["paused_until"]``: epoch
  seconds, None when not paused) - unless it asks for more than ``max_retry_after_s`` (120 s):
  then the call fails at once as ``LLMError("rate_limit")`` and nothing is paused; 5xx and
  timeouts back off and retry. ``stats()`` also gives ``window_requests`` / ``window_tokens``.
- Budget: a call is sent only after its worst-case cost (prompt upper bound + max_tokens x
  choices + 2 tokens of slack, at full prices) is reserved within the run cap and the model cap;
  params that multiply the output (``n``, ``best_of``) must be 1 (DeploymentConfig refuses
  others). Spend is settled to the actual cost, checked (:mod:`workers.llm.accounting`): never
  below the floor (our own count of the prompt at the input price + of the reply at the output
  price), and an answer whose usage is impossible (missing, non-integer, negative, zero, below a
  quarter of our count, above our bounds, or with a negative/NaN cost figure) is charged its
  worst case and leaves a ``usage_rejected`` event. The journal ``RUN_DIR/gateway/ledger.jsonl`` is
  fsync'd, so a killed gateway/ledger restarted from the run folder continues from the exact
  spend (open reservations of the dead process are charged at worst case).
- Shards: N gateway shards of a deployment hold shares of its RPM/TPM quota and dollar leases
  from one QuotaActor; the shares never sum past the quota and the leases are ledger reservations,
  so both guarantees above hold across shards; a dead shard's lease is charged in full.
- Idempotency: a repeated ``request.call_key`` returns the recorded response
  (``served_from="ledger"``, cost 0), across restarts too. With ``cache=True`` identical
  requests (model, params, messages) are served from the ledger (``"cache"``, cost 0).
- Records: one ``llm_calls`` row per call, written by the gateway (batched, flushed every
  second and on close) with the agent's context from the request. Errors reach the caller as
  ``LLMError(kind)`` with ``kind`` in ``recap.llm.ERROR_KINDS``; API keys never appear in
  records, logs or error messages; a base URL's credentials (``user:password@``, ``key=`` /
  ``api_key=`` / ``token=`` query parameters) are stripped from every name (``deployment``,
  file names, ledger owners) while the provider gets the real URL; a reply that echoes the
  key or those credentials reaches the agent, the ledger, the cache and the records with
  ``[REDACTED]`` in their place. ``events`` rows (source ``gateway``): ``retry`` / ``call_failed``
  per failed attempt (detail: kind, status, call_key), ``usage_rejected`` per answer whose usage
  was impossible (detail: problems, reported figures, charged), ``orphans_charged`` when a restarted
  gateway charges its predecessor's open reservations, ``ledger_restored`` when a restarted
  BudgetActor did.
- Restarts (pipeline): the actors are created with ``max_restarts=-1`` and a few task
  retries, so a killed gateway or budget actor comes back from the run folder and the calls
  it had in flight are re-sent (served from the ledger when they had been settled); the
  gateways find the BudgetActor by name (``GatewayActor(..., budget="<name>")``). API keys
  reach the actors as a ``SecretEnv`` constructor argument, never through ``runtime_env``
  (which Ray logs).
- Test doubles: ``offline/expert``, ``offline/random``, ``offline/replay`` (litellm custom
  provider) and ``workers.llm.offline.fake_server``; their records carry ``test_double=True``.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the Ray-backed names (actors, client) stay Any to a type checker, as Ray's classes are
    from workers.gateway.blocking import BlockingGateway
    from workers.gateway.core import DeploymentGateway
    from workers.gateway.ledger import BudgetLedger, LocalBudget
    from workers.llm.pricing import Price, PriceError, PriceTable, require_prices
    from workers.llm.providers import DeploymentConfig, DeploymentConfigError

__all__ = [
    "BlockingGateway",
    "BudgetActor",
    "BudgetLedger",
    "DeploymentConfig",
    "DeploymentConfigError",
    "DeploymentGateway",
    "GatewayActor",
    "GatewayClient",
    "LocalBudget",
    "Price",
    "QuotaActor",
    "PriceError",
    "PriceTable",
    "RunGateways",
    "require_prices",
]

#: public name -> the module that defines it. Every name is imported on first use: an episode
#: worker unpickles a ``GatewayClient`` (which imports this package) and needs nothing else of
#: the gateway; the core, the ledger, the price table and the provider configs would cost each
#: worker process pydantic, yaml and more (issue 37, item 3). The Ray-backed names also keep
#: the core usable without Ray.
_MODULE_OF = {
    "BudgetActor": "workers.gateway.actors",
    "GatewayActor": "workers.gateway.actors",
    "QuotaActor": "workers.gateway.actors",
    "RunGateways": "workers.gateway.actors",
    "GatewayClient": "workers.gateway.client",
    "BlockingGateway": "workers.gateway.blocking",
    "DeploymentGateway": "workers.gateway.core",
    "BudgetLedger": "workers.gateway.ledger",
    "LocalBudget": "workers.gateway.ledger",
    "Price": "workers.llm.pricing",
    "PriceError": "workers.llm.pricing",
    "PriceTable": "workers.llm.pricing",
    "require_prices": "workers.llm.pricing",
    "DeploymentConfig": "workers.llm.providers",
    "DeploymentConfigError": "workers.llm.providers",
}


def __getattr__(name: str) -> Any:
    """A public name, imported from its module on first use (see :data:`_MODULE_OF`)."""
    if name in _MODULE_OF:
        return getattr(importlib.import_module(_MODULE_OF[name]), name)
    raise AttributeError(f"module 'workers.gateway' has no attribute {name!r}")
