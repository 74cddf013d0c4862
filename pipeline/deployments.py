"""A sweep model entry as the gateway's deployment config, built (and so checked) in one place.

Why a module of its own: the preflight builds every entry's config before anything is written
(generation params and test-double options within their ranges) and the gateway backend builds
the same configs to start its actors; both import this, neither imports the other.
"""

from __future__ import annotations

from typing import Any

from pydantic import ValidationError

from pipeline.errors import SpecError
from pipeline.spec import ModelSpec
from workers.llm.offline.knobs import Knobs, OfflineOptionsError
from workers.llm.providers import DeploymentConfig


def deployment_config(m: ModelSpec, where: str) -> Any:
    """The gateway's config for one sweep model entry; errors name the entry."""

    if m.options and not m.test_double:
        raise SpecError(f"{where} ({m.name}): 'options' are for offline/ test doubles only")
    if m.test_double:
        try:
            Knobs.from_options(m.options)
        except OfflineOptionsError as exc:
            raise SpecError(f"{where} ({m.name}): {exc}") from None
    try:
        return DeploymentConfig(**m.deployment_fields())
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(x) for x in err.get("loc", ()))
        raise SpecError(
            f"{where} ({m.name}): {loc + ': ' if loc else ''}{err.get('msg', 'invalid').removeprefix('Value error, ')}"
        ) from None
    except ValueError as exc:
        raise SpecError(f"{where} ({m.name}): {exc}") from None
