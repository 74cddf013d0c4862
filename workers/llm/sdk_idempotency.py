"""No random idempotency key per request from an OpenAI SDK client that never sends one.

Why: the OpenAI SDK gives every non-GET request an idempotency key,
``f"stainless-python-retry-{uuid.uuid4()}"`` (``openai._base_client.BaseClient._idempotency_key``,
called from ``request`` in both the sync and the async client), so that its own retries resend the
same key. The key reaches the wire only through the client's ``_idempotency_header``
(``BaseClient._build_headers``), which the SDK's OpenAI and Azure clients leave None: for them the
key is read by nothing, yet each call pays a ``uuid4`` (an ``os.urandom`` system call), about 2 %
of the gateway's CPU per call in the issue-37 profile. Our calls never retry inside the SDK
either (``max_retries=0``, :mod:`workers.llm.calling`).

:func:`install` wraps ``_idempotency_key``: a client without an idempotency header gets a fixed
placeholder; a client that has one (a subclass that sends the header) gets the SDK's own random
key, unchanged.
"""

from __future__ import annotations

from typing import Any

#: the key of a request whose client sends no idempotency header (never sent, never read)
UNSENT_KEY = "stainless-python-retry-unsent"
_installed = False


def install() -> bool:
    """Wrap the SDK's idempotency-key maker (once per process); False when its layout differs."""
    global _installed
    if _installed:
        return True
    try:
        from openai._base_client import BaseClient
    except ImportError:
        return False
    original = getattr(BaseClient, "_idempotency_key", None)
    if original is None or not callable(original) or "_idempotency_header" not in getattr(BaseClient, "__annotations__", {}):
        return False

    def _idempotency_key(self: Any) -> str:
        if getattr(self, "_idempotency_header", None) is None:
            return UNSENT_KEY
        return original(self)

    _idempotency_key.__wrapped__ = original  # type: ignore[attr-defined]
    BaseClient._idempotency_key = _idempotency_key  # type: ignore[method-assign]
    _installed = True
    return True
