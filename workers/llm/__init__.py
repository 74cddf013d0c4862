"""Everything about talking to one model provider, without Ray.

- :mod:`workers.llm.litellm_import` imports litellm offline and quiet (readers of its types use it).
- :mod:`workers.llm.litellm_setup`  that import plus the ``offline/`` test-double provider
  registered (every call, real or fake, takes litellm's path).
- :mod:`workers.llm.providers`      :class:`DeploymentConfig` (model + base URL + key env name +
  limits + generation params) and the keyword arguments one litellm call gets.
- :mod:`workers.llm.calling`        one attempt through ``litellm.acompletion``/``completion``
  (provider SDK retries switched off) and parsing of its usage.
- :mod:`workers.llm.accounting`     the worst case of a request; the provider's usage checked
  (impossible usage -> worst case), the cost of one answer (never below our floor), its row.
- :mod:`workers.llm.fingerprint`    stable hashes of messages / requests (cache, replay).
- :mod:`workers.llm.errors`         provider exception -> :data:`recap.llm.ERROR_KINDS`, secret
  scrubbing.
- :mod:`workers.llm.pricing`        the repo's price table (``workers/pricing/prices.yaml``),
  integer pico-dollar costs, :func:`require_prices`.
- :mod:`workers.llm.tokens`         offline prompt-token counts and the worst-case bound.
- :mod:`workers.llm.offline`        ``offline/expert``, ``offline/random``, ``offline/replay``.
- :mod:`workers.llm.direct`         :class:`LiteLLMClient`, a Ray-free ``LLMClient``.

The loopback OpenAI-compatible test server with quotas and faults is a test utility:
:mod:`workers.llm.offline.fake_server`. The gateway (:mod:`workers.gateway`) builds admission control, budgets and the ledger on top.
"""
