"""What every Ray worker process of a run does first (Ray's ``worker_process_setup_hook``, named in
:func:`pipeline.raysetup.runtime_env`): keep Ray from importing pyarrow, numpy and pydantic into a
process that never uses them.

Why: when a worker process first (de)serialises anything, Ray builds its serialisation context
and, through ``ray.util.serialization_addons.apply``, registers its extra serialisers for
pydantic (FastAPI's v1 model fields), Starlette and Arrow (Ray Data's zero-copy tables) - importing
pydantic, pyarrow and with it numpy, whether or not the process ever holds one of their objects.
An episode worker holds none (its rows reach the sink as plain data): those imports were
~40 MB of its ~70 MB (issue 37, item 3). So the hook swaps ``apply`` for one that registers each
extra serialiser only when its library is already imported in the process when the context is
built (the sink and the gateways import pyarrow with their module, before it): a value of a
library the process never imported cannot be among what it sends. Registering fewer serialisers
changes no result: without Ray's own one an object is pickled by its own ``__reduce__``, which
every one of these types has (Ray's are shortcuts). Another Ray layout (a private name gone):
Ray's own ``apply`` stays.
"""

from __future__ import annotations

import sys
from typing import Any

#: Ray's ``runtime_env["worker_process_setup_hook"]`` value: this module's :func:`setup`
HOOK = f"{__name__}.setup"


def setup() -> None:
    """Install :func:`lean_apply` in place of Ray's serialisation add-ons (in this process only)."""
    try:
        from ray.util import serialization_addons
    except ImportError:  # another Ray layout: its own add-ons stay
        return
    if getattr(serialization_addons.apply, "__name__", "") != lean_apply.__name__:
        serialization_addons.apply = lean_apply


def lean_apply(serialization_context: Any) -> None:
    """Ray's ``serialization_addons.apply``, each add-on only when its library is already loaded."""
    from ray.util import serialization_addons

    if "pydantic" in sys.modules:
        from ray._common.pydantic_compat import register_pydantic_serializers

        register_pydantic_serializers(serialization_context)
    if "starlette" in sys.modules:
        serialization_addons.register_starlette_serializer(serialization_context)
    if "pyarrow" in sys.modules and sys.platform != "win32":
        from ray._private.arrow_serialization import _register_custom_datasets_serializers

        _register_custom_datasets_serializers(serialization_context)
