"""A demonstration's replies by method key: hand-written ones, else derived from its script by
each registered method.

Why a mapping over the method registry: a benchmark writes its solved example once
(:class:`recap.demo_script.DemoScript`) and every method registered in
:data:`recap.method_registry.METHODS`, a plug-in's included, answers for its own key from it,
so no list of methods is kept here and nothing has to be imported first to fill one.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping

from recap.demo_script import DemoScript, Replies
from recap.method_registry import METHODS


class DemoReplies(Mapping[str, Replies]):
    """Replies by method key: hand-written ones first (a method whose replies cannot be derived,
    or a test's override), then those derived from the script by each registered method's agent
    class that can derive them, in registration order."""

    explicit: dict[str, Replies]
    script: DemoScript | None

    def __init__(self, explicit: Mapping[str, Replies] | None = None, script: DemoScript | None = None) -> None:
        if isinstance(explicit, DemoReplies):  # re-wrapped: keep its overrides and its script
            script = script or explicit.script
            explicit = explicit.explicit
        self.explicit = dict(explicit or {})
        self.script = script

    def _derived(self, key: str) -> Replies | None:
        if self.script is None or key not in METHODS:
            return None
        return METHODS[key].agent_cls.demo_replies(self.script)

    def __getitem__(self, key: str) -> Replies:
        if key in self.explicit:
            return self.explicit[key]
        replies = self._derived(key)
        if replies is None:
            raise KeyError(key)
        return replies

    def __iter__(self) -> Iterator[str]:
        keys = list(self.explicit)
        if self.script is not None:
            keys += [name for name in METHODS.names() if name not in keys and self._derived(name) is not None]
        return iter(keys)

    def __len__(self) -> int:
        return sum(1 for _ in self)

    def __repr__(self) -> str:
        return f"DemoReplies({dict(self)!r})"
