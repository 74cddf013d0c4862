"""Blocksworld, the small benchmark that lives in the pure ``recap`` package, for the registry.

Why an adapter: :mod:`recap.blocksworld` may import nothing of ``workers`` (the layering), so
its ``BENCHMARK`` cannot subclass :class:`workers.envs.registry.Benchmark`; this module gives
it the declared hooks (defaults but the spelling of its ids: its instances are generated, it
reads no data folder and has no per-method options).
"""

from __future__ import annotations

from typing import Any

from recap.blocksworld import BENCHMARK as _PURE
from recap.env import Environment
from workers.envs.registry import Benchmark


class BlocksworldBenchmark(Benchmark):
    """The registry's adapter for the built-in Blocksworld of :mod:`recap.blocksworld` (the pure
    core cannot import the registry, so the adapter lives here)."""

    name = _PURE.name

    def list_instances(self, selector: str | None = None) -> list[str]:
        return _PURE.list_instances(selector)

    def make(self, instance_id: str, **options: Any) -> Environment:
        return _PURE.make(instance_id, **options)

    def canonical_id(self, instance_id: str) -> str:
        """Numbers without leading zeros (the pure core's rule)."""
        return _PURE.canonical_id(instance_id)


BENCHMARK = BlocksworldBenchmark()
