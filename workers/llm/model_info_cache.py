"""Remember litellm's "model not mapped" answers, as litellm already remembers its found ones.

Why: after every call litellm prices the reply for its ``response_cost`` (which we keep as
``provider_cost_usd``, a cross-check): that looks the model up in its cost map several times
per call through two ``functools.lru_cache`` functions (``litellm.utils._cached_get_model_info``
and ``cached_get_model_info_helper``). An ``lru_cache`` keeps results, not exceptions, so for a
model the map does not know - a self-hosted or OpenAI-compatible model, every test double - each
lookup redoes the whole search (provider aliases, capability fallbacks) and raises again:
profiled on the fake server's model it was about a tenth of the gateway's CPU per call
(issue 37).

This wraps both functions: a lookup that raised is answered by raising a new exception of the
same type and arguments, without searching, until litellm's cost map changes (the key holds
litellm's own mutation counter, ``get_model_cost_mutation_generation``, which every
registration bumps; ``cache_clear`` clears ours with theirs). Found models go to litellm's cache
as before: what any lookup returns or raises is unchanged.

Before every chat call litellm also asks for the model's info once more, uncached
(``litellm.main.responses_api_bridge_check`` calls ``get_model_info_helper``: does the model need
the Responses API?), about 2 % of the gateway's CPU per call on an unmapped model (issue 37).
:func:`install` points that name at :func:`bridge_lookup`: the same answer from litellm's own
cached lookup (``cached_get_model_info_helper``, which litellm keys on the same arguments and
clears with every cost-map change), as a copy - the bridge check may write ``mode`` into it - or
the same exception.
"""

from __future__ import annotations

import threading
from typing import Any

_MAX_ENTRIES = 1024
_installed = False


class NegativeCache:
    """``fn`` with its exceptions remembered per (arguments, cost-map generation)."""

    def __init__(self, fn: Any, generation: Any):
        self.fn = fn
        self.generation = generation
        self.misses: dict[tuple, tuple[type[BaseException], tuple]] = {}
        self.lock = threading.Lock()
        self.__wrapped__ = fn
        self.__name__ = getattr(fn, "__name__", "lookup")
        self.__doc__ = getattr(fn, "__doc__", None)

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        try:
            key = (args, tuple(sorted(kwargs.items())), self.generation())
            hash(key)
        except TypeError:  # unhashable arguments: litellm's own cache would refuse them too
            return self.fn(*args, **kwargs)
        known = self.misses.get(key)
        if known is not None:
            exc_type, exc_args = known
            raise exc_type(*exc_args)
        try:
            return self.fn(*args, **kwargs)
        except Exception as exc:
            if _rebuildable(exc):
                with self.lock:
                    if len(self.misses) >= _MAX_ENTRIES:
                        self.misses.clear()
                    self.misses[key] = (type(exc), exc.args)
            raise

    def cache_clear(self) -> None:
        with self.lock:
            self.misses.clear()
        self.fn.cache_clear()

    def cache_info(self) -> Any:
        return self.fn.cache_info()


def _rebuildable(exc: Exception) -> bool:
    """True when ``type(exc)(*exc.args)`` makes an equal exception (so raising it again is faithful)."""
    try:
        again = type(exc)(*exc.args)
    except Exception:
        return False
    return type(again) is type(exc) and again.args == exc.args and str(again) == str(exc)


def make_bridge_lookup(uncached: Any, cached: Any) -> Any:
    """``get_model_info_helper`` answered from ``cached`` (litellm's ``cached_get_model_info_helper``,
    wrapped in a :class:`NegativeCache`) when called as the bridge check calls it, as a fresh copy;
    any other call (an ``api_key``) goes to ``uncached`` as before."""

    def get_model_info_helper(
        model: str, custom_llm_provider: str | None = None, api_base: str | None = None, api_key: str | None = None
    ) -> Any:
        if api_key is not None:
            return uncached(model=model, custom_llm_provider=custom_llm_provider, api_base=api_base, api_key=api_key)
        return dict(cached(model=model, custom_llm_provider=custom_llm_provider, api_base=api_base))

    get_model_info_helper.__wrapped__ = uncached  # type: ignore[attr-defined]
    return get_model_info_helper


def install(litellm: Any) -> bool:
    """Wrap litellm's two model-info caches (once per process); False when its layout differs
    (then nothing is changed)."""
    global _installed
    if _installed:
        return True
    utils: Any = getattr(litellm, "utils", None)
    cost_calculator: Any = getattr(litellm, "cost_calculator", None)
    generation = getattr(utils, "get_model_cost_mutation_generation", None)
    info = getattr(utils, "_cached_get_model_info", None)
    helper = getattr(utils, "cached_get_model_info_helper", None)
    if generation is None or info is None or helper is None or cost_calculator is None:
        return False
    if not hasattr(info, "cache_clear") or not hasattr(helper, "cache_clear"):
        return False
    wrapped_info, wrapped_helper = NegativeCache(info, generation), NegativeCache(helper, generation)
    utils._cached_get_model_info = wrapped_info
    utils.cached_get_model_info_helper = wrapped_helper
    utils._cached_get_model_info_helper = wrapped_helper
    if getattr(cost_calculator, "cached_get_model_info_helper", None) is helper:
        cost_calculator.cached_get_model_info_helper = wrapped_helper
    main = getattr(litellm, "main", None)
    uncached = getattr(utils, "get_model_info_helper", None)
    if main is not None and uncached is not None and getattr(main, "get_model_info_helper", None) is uncached:
        main.get_model_info_helper = make_bridge_lookup(uncached, wrapped_helper)
    public = getattr(utils, "get_model_info", None)
    if public is not None and getattr(public, "cache_clear", None) == info.cache_clear:
        public.cache_clear = wrapped_info.cache_clear  # litellm.get_model_info.cache_clear() clears ours too
    _installed = True
    return True
