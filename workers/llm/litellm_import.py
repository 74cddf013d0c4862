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

            _use_bundled_encodings(litellm)
            litellm.suppress_debug_info = True
            litellm.telemetry = False
            # never try to download a Hugging Face tokenizer (no network at run time)
            litellm.disable_hf_tokenizer_download = True
            logging.getLogger("LiteLLM").setLevel(logging.ERROR)
            _litellm = litellm
    return _litellm


def _use_bundled_encodings(litellm: Any) -> None:
    """Point tiktoken at the encodings bundled with litellm (``TIKTOKEN_CACHE_DIR``), by litellm's
    own rule (``litellm/litellm_core_utils/default_encoding.py``: ``CUSTOM_TIKTOKEN_CACHE_DIR``
    if set, else the package's ``litellm_core_utils/tokenizers`` folder), so that token counts
    never download (:mod:`workers.llm.tokens`).

    Why not import that module, as litellm does where it needs its default encoding: importing
    it also loads ``cl100k_base`` (~38 MB of PSS in every process that imports litellm - the
    gateway, the driver), which a run whose models are not OpenAI's, or use another encoding,
    never reads; litellm itself loads it lazily (``litellm._lazy_imports.get_default_encoding``),
    and so does :func:`workers.llm.tokens._encoding_for` (issue 37, item 3)."""
    custom = os.getenv("CUSTOM_TIKTOKEN_CACHE_DIR")
    if custom:
        os.makedirs(custom, exist_ok=True)
        os.environ["TIKTOKEN_CACHE_DIR"] = custom
        return
    from importlib import resources

    os.environ["TIKTOKEN_CACHE_DIR"] = str(resources.files(litellm).joinpath("litellm_core_utils/tokenizers"))
