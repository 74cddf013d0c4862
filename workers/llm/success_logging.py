"""No litellm success-logging work per call when nothing listens to it.

Why: after every successful async call litellm schedules a task that builds its "standard
logging payload" (a copy of the messages with base64 cut out, metadata, usage, cost, tags) and
hands it to the registered success callbacks and its response cache. We register none and use no
litellm cache (our records are the ``llm_calls`` rows the gateway writes; the reply's cost is
set on the response before that task runs), so the payload is built for nobody: profiled through
the gateway at 16 workers it was the largest single litellm frame (issue 37).

:func:`install` wraps litellm's scheduler (``litellm.utils._schedule_async_success_logging``):
while every success-callback list is empty and ``litellm.cache`` is None the task is not
created; as soon as anything registers a callback or a cache, litellm's own scheduler runs
again, unchanged.

:func:`install` also wraps ``Logging._record_zero_cost_diagnostic``: after pricing a reply whose
cost is zero or could not be computed (every reply of a model litellm's cost map does not know:
self-hosted models, the test doubles), litellm looks the model's price entry up again to say why,
stores the finding in ``model_call_details["zero_cost_diagnostic"]`` - read only by the standard
logging payload above - and logs it as a warning. While nobody listens and the ``LiteLLM`` logger
is quiet at WARNING (:mod:`workers.llm.litellm_import` sets it to ERROR) nothing reads either, so
the lookup is skipped: profiled on the fake server's model it was about 3 % of litellm's CPU per
call (issue 37). The reply's ``response_cost`` - our ``provider_cost_usd`` - is computed before
the diagnostic and is unchanged.
"""

from __future__ import annotations

import logging
from typing import Any

#: litellm's lists of success listeners (any of them non-empty: the task must run)
LISTENER_LISTS = ("callbacks", "success_callback", "_async_success_callback", "service_callback")
_installed = False
_diagnostic_installed = False


def nobody_listens(litellm: Any) -> bool:
    """True when no success callback of any kind is registered and no litellm cache is set."""
    if getattr(litellm, "cache", None) is not None:
        return False
    return not any(getattr(litellm, name, None) for name in LISTENER_LISTS)


def install(litellm: Any) -> bool:
    """Wrap litellm's success-logging scheduler (once per process); False when its layout differs."""
    global _installed
    if _installed:
        return True
    utils = getattr(litellm, "utils", None)
    original = getattr(utils, "_schedule_async_success_logging", None)
    if original is None or not callable(original):
        return False

    def _schedule_async_success_logging(*args: Any, **kwargs: Any) -> None:
        if nobody_listens(litellm):
            return None
        return original(*args, **kwargs)

    _schedule_async_success_logging.__wrapped__ = original  # type: ignore[attr-defined]
    utils._schedule_async_success_logging = _schedule_async_success_logging  # type: ignore[union-attr]
    _installed = True
    return True


def diagnostic_unread(litellm: Any) -> bool:
    """True when nothing would read a zero-cost diagnostic: nobody listens (:func:`nobody_listens`)
    and litellm's logger would drop its warning."""
    return nobody_listens(litellm) and not logging.getLogger("LiteLLM").isEnabledFor(logging.WARNING)


def install_zero_cost_diagnostic(litellm: Any) -> bool:
    """Wrap litellm's zero-cost diagnostic (once per process); False when its layout differs."""
    global _diagnostic_installed
    if _diagnostic_installed:
        return True
    try:
        from litellm.litellm_core_utils.litellm_logging import Logging
    except ImportError:
        return False
    original = getattr(Logging, "_record_zero_cost_diagnostic", None)
    if original is None or not callable(original):
        return False

    def _record_zero_cost_diagnostic(self: Any, *args: Any, **kwargs: Any) -> None:
        if diagnostic_unread(litellm):
            return None
        return original(self, *args, **kwargs)

    _record_zero_cost_diagnostic.__wrapped__ = original  # type: ignore[attr-defined]
    Logging._record_zero_cost_diagnostic = _record_zero_cost_diagnostic  # type: ignore[method-assign]
    _diagnostic_installed = True
    return True
