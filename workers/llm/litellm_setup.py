"""litellm ready for calls: imported offline and quiet, with the ``offline/`` provider registered.

Why a module for this: every process that makes model calls (driver, Ray actors) gets litellm
through :func:`get_litellm` so the test doubles are registered as a litellm custom provider
before the first call. The import itself (offline cost map, quiet logging) is
:mod:`workers.llm.litellm_import`; this module only adds the registration, so the offline
provider can use the token counters (which read litellm too) without an import cycle.
"""

from __future__ import annotations

import threading
from typing import Any

from workers.llm.litellm_import import import_litellm

_lock = threading.Lock()
_ready: Any = None


def get_litellm() -> Any:
    """The configured litellm module with the offline provider registered (on first use)."""
    global _ready
    if _ready is not None:
        return _ready
    with _lock:
        if _ready is None:
            litellm = import_litellm()
            # the offline test doubles load with litellm, not with every module that may call a model
            from workers.llm.offline.provider import register_offline_provider

            register_offline_provider(litellm)
            # a reply's tool calls are read whatever the model wrote in them (never a 500)
            from workers.llm.tool_call_guard import install

            install(litellm)
            # the OpenAI SDK's per-message type walk, a no-op for plain-JSON chat requests, skipped
            from workers.llm import sdk_fast_path

            sdk_fast_path.install()
            # no uuid4 per request for an idempotency key the SDK's clients never send
            from workers.llm import sdk_idempotency

            sdk_idempotency.install()
            # "model not mapped" remembered like a found model (litellm prices every reply)
            from workers.llm import model_info_cache

            model_info_cache.install(litellm)
            # no success-logging task per call while no callback or cache listens
            from workers.llm import success_logging

            success_logging.install(litellm)
            success_logging.install_zero_cost_diagnostic(litellm)
            _ready = litellm
    return _ready
