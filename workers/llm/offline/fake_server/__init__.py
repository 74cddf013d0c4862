"""TEST DOUBLE: a loopback OpenAI-compatible chat server with quotas and injected faults.

Why: the gateway's rate limiting, retries and error classes must be shown against a real
HTTP exchange through litellm's own client, without a paid provider. The server:

- serves ``POST /v1/chat/completions`` on 127.0.0.1 only (random port by default);
- enforces RPM/TPM over a sliding window (``window_s``; 60 s like providers, scaled down in
  tests) and answers 429 with ``Retry-After`` (seconds) and ``retry-after-ms``;
- counts tokens with the documented estimate of :mod:`workers.llm.tokens` and reports usage,
  with the prompt cache of a provider's rule (:mod:`workers.llm.prompt_cache`: ``openai``
  automatic prefixes, ``anthropic`` explicit ``cache_control`` breakpoints with writes and
  reads, ``deepseek`` hit/miss prefix units; each in that provider's own usage fields, with a
  TTL so idle episodes lose their cache), chosen per deployment: ``cache_rules`` maps a model
  name to a rule, other models get ``cache_rule`` (default ``lcp``: the longest common prefix
  with earlier prompts, chars / 4, in ``prompt_tokens_details.cached_tokens``).
  ``advance(seconds)`` moves the cache's clock (TTL tests without sleeping); message content
  may be a string or a list of text blocks (litellm's format for ``cache_control``);
- answers 400 ``context_length_exceeded`` (OpenAI error shape) above ``max_context_tokens``;
- injects latency, 5xx, hangs (timeouts), empty and malformed bodies - at random with
  ``fault_rates`` (seeded) or per request with a directive in the last message:
  ``FAKE:<mode>`` (always) or ``FAKE:<mode>*<n>`` (the first n arrivals of that exact request),
  modes: 429 500 502 503 hang ctx 400 401, the unreadable-200 modes of :data:`UNREADABLE_MODES`
  (empty malformed notjson html nochoices nullchoices nomessage nullcontent: a reply generated
  and billed, then unusable), ``textplain`` (a good reply under a text/plain content type), and
  the lying-provider modes
  ``retrylong`` (429 with ``Retry-After: long_retry_after_s``, 3600 by default), ``echokey`` (the
  reply text repeats the API key the request carried), ``negusage`` / ``zerousage`` /
  ``hugeusage`` / ``fracusage`` / ``nousage`` / ``negcached`` (the usage block reports negative, zero,
  huge, non-integer or no token counts, or negative cached tokens; the reply itself is normal);
  the hostile tool-call modes of :data:`HOSTILE_CALL_MODES` (to a request with tools: arguments
  nested 200,000 deep as a string or inside the body, 5 MB of arguments, repeated call ids, a null
  function, content beside the calls, finish ``tool_calls`` with no call, arguments as an object,
  a 1 MB call id);
  ``usage_override`` and these modes name the cache counts ``cached_tokens`` (reads) and
  ``cache_write_tokens`` (writes), reported in the rule's own fields;
- replies with a fixed, configurable text (truncated at ``max_tokens``, finish_reason length),
  one choice per ``n`` of the request (usage counts every choice, like OpenAI);
- ``usage_override`` replaces fields of every reply's usage block (``None`` drops a field);
  ``retry_after_s`` replaces the Retry-After of every 429;
- with ``require_api_key`` set, answers 401 echoing the wrong key it got (tests that keys are
  scrubbed before anything is written);
- keeps a log of every arrival (``GET /fake/log``), so tests check windows server-side.

Run standalone: ``python -m workers.llm.offline.fake_server --port 0 --rpm 60 --tpm 20000 --window-s 6``.
"""

from workers.llm.offline.fake_server.config import FakeCall, FakeServerConfig, window_maxima
from workers.llm.offline.fake_server.faults import DEFAULT_REPLY, FAULT_MODES, HOSTILE_CALL_MODES, UNREADABLE_MODES
from workers.llm.offline.fake_server.server import HOST, FakeServer

__all__ = [
    "DEFAULT_REPLY",
    "FAULT_MODES",
    "HOST",
    "HOSTILE_CALL_MODES",
    "UNREADABLE_MODES",
    "FakeCall",
    "FakeServer",
    "FakeServerConfig",
    "window_maxima",
]
