"""Import litellm once per process, offline and quiet (nothing of ours registered yet).

Why a module for this: litellm fetches its model cost map from the internet on import (and
retries for seconds without network) unless ``LITELLM_LOCAL_MODEL_COST_MAP`` is set first, and
it prints help banners on errors. Modules that only read litellm (its exception classes in
:mod:`workers.llm.errors`, its bundled tokenizer files in :mod:`workers.llm.tokens`) import it
through :func:`import_litellm`; modules that make calls use
:func:`workers.llm.litellm_setup.get_litellm`, which adds the ``offline/`` provider on top.
Keeping the bare import apart keeps those readers out of an import cycle with the offline
provider (which counts tokens).
"""

from __future__ import annotations

import logging
import os
import threading
from typing import Any

os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")

_lock = threading.Lock()
_litellm: Any = None


def import_litellm() -> Any:
    """The litellm module, configured offline and quiet (imported on first use)."""
    global _litellm
    if _litellm is not None:
        return _litellm
    with _lock:
        if _litellm is None:
            import litellm  # the one place litellm is imported: offline, quiet, once

            # importing this module points TIKTOKEN_CACHE_DIR at litellm's bundled encodings
            import litellm.litellm_core_utils.default_encoding  # noqa: F401

            litellm.suppress_debug_info = True
            litellm.telemetry = False
            # never try to download a Hugging Face tokenizer (no network at run time)
            litellm.disable_hf_tokenizer_download = True
            logging.getLogger("LiteLLM").setLevel(logging.ERROR)
            _litellm = litellm
    return _litellm
