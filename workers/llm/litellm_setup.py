"""Import litellm once per process: offline, quiet, with the ``offline/`` provider registered.

Why a module for this: litellm fetches its model cost map from the internet on import (and
retries for seconds without network) unless ``LITELLM_LOCAL_MODEL_COST_MAP`` is set first, and
it prints help banners on errors. Every process that makes model calls (driver, Ray actors)
imports litellm through :func:`get_litellm` so those settings are never forgotten, and so the
test doubles are registered as a litellm custom provider before the first call.
"""

from __future__ import annotations

import logging
import os
import threading
from typing import Any

os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")

_lock = threading.Lock()
_litellm: Any = None


def get_litellm() -> Any:
    """The configured litellm module (imported on first use)."""
    global _litellm
    if _litellm is not None:
        return _litellm
    with _lock:
        if _litellm is None:
            import litellm
            # importing this module points TIKTOKEN_CACHE_DIR at litellm's bundled encodings
            import litellm.litellm_core_utils.default_encoding  # noqa: F401

            litellm.suppress_debug_info = True
            litellm.telemetry = False
            # never try to download a Hugging Face tokenizer (no network at run time)
            litellm.disable_hf_tokenizer_download = True
            logging.getLogger("LiteLLM").setLevel(logging.ERROR)

            from workers.llm.offline.provider import register_offline_provider

            register_offline_provider(litellm)
            _litellm = litellm
    return _litellm
