"""A named, typed registry resolved on first use: the one mechanism behind methods and benchmarks.

Why one mechanism: methods and benchmarks used to be registered three different ways (a dict
literal, a side-effect import, importlib strings). Here each kind is a :class:`Registry` whose
built-ins are listed in one explicit table next to it, each as a reference
``"package.module[:ATTRIBUTE]"`` that is imported only when the name is first used, so

* a name is known (listed, checked, reported as unknown) without importing its code, and an
  optional dependency missing for one entry affects that entry only;
* every process that imports the registry's module has the same built-ins (Ray workers
  included), without relying on some other module having been imported first;
* the list of names is the registry itself (:meth:`Registry.names`), never a copy.

Plug-ins and tests register more at run time, with the call form ``reg.register(name, obj)``
or the decorator form ``@reg.register(name)``, and remove them with :meth:`Registry.unregister`.
The design follows Inspect AI's registry (``registry_add`` / ``registry_lookup``: objects
looked up by kind and name, packages loaded on demand by module name), with one registry object
per kind instead of one global table. A registry reads like a dict from name to the resolved
object (``name in reg``, ``reg[name]``, ``list(reg)``, ``reg.items()``), except that
:meth:`Registry.get` raises for an unknown name instead of returning a default.
"""

from __future__ import annotations

import importlib
import threading
from collections.abc import Callable, Iterator
from typing import Generic, TypeVar, overload

T = TypeVar("T")
_Obj = TypeVar("_Obj")


class Registry(Generic[T]):
    """Entries by name, in registration order, each resolved to a ``T`` on first use.

    * ``kind`` names the entries in messages (``unknown method 'x'; known: a, b``);
    * ``coerce(name, obj)`` turns what a registration gave (the object itself or what its
      reference names) into a ``T`` and checks it, raising for anything else; default: as is;
    * ``error`` is the exception type of every refusal (a name registered twice, unregistering
      a name that is not there) and, unless ``unknown_error`` is given, of a lookup of a name
      nothing registers, so callers catch their own kind's error;
    * ``attribute`` is the attribute a reference without ``:ATTRIBUTE`` names in its module;
    * ``keep`` (default true) keeps what a name resolved to; false reads a reference string's
      attribute again at every lookup (the module is imported once either way), for values that
      are plain module attributes a test or a plug-in may replace (data folders).
    """

    def __init__(
        self,
        kind: str,
        *,
        coerce: Callable[[str, object], T] | None = None,
        error: type[Exception] = KeyError,
        unknown_error: type[Exception] | None = None,
        attribute: str | None = None,
        keep: bool = True,
    ) -> None:
        self.kind = kind
        self._keep = keep
        self._coerce = coerce
        self._error = error
        self._unknown_error = unknown_error or error
        self._attribute = attribute
        self._lock = threading.RLock()
        self._sources: dict[str, object] = {}
        self._resolved: dict[str, T] = {}

    # -- registering ---------------------------------------------------------------------------
    @overload
    def register(self, name: str) -> Callable[[_Obj], _Obj]: ...
    @overload
    def register(self, name: str, source: object) -> None: ...
    def register(self, name: str, source: object = None) -> Callable[[_Obj], _Obj] | None:
        """Register ``source`` as ``name``: the object itself, or a reference string
        ``"package.module[:ATTRIBUTE]"`` imported on first use. Without ``source``, a decorator
        that registers the decorated object and returns it unchanged. A name is registered
        once; :meth:`unregister` it first to replace it."""
        if source is None:

            def decorate(obj: _Obj) -> _Obj:
                self.register(name, obj)
                return obj

            return decorate
        with self._lock:
            if name in self._sources:
                raise self._error(f"{self.kind} {name!r} is already registered")
            self._sources[name] = source
        return None

    def unregister(self, name: str) -> None:
        """Forget ``name`` and what it resolved to (tests and plug-ins that go away)."""
        with self._lock:
            if name not in self._sources:
                raise self._error(f"{self.kind} {name!r} is not registered")
            del self._sources[name]
            self._resolved.pop(name, None)

    # -- reading -------------------------------------------------------------------------------
    def names(self) -> list[str]:
        """The registered names, in registration order (built-ins first); imports nothing."""
        with self._lock:
            return list(self._sources)

    def unknown(self, name: str) -> str:
        """The one wording of a lookup of a name nothing registers."""
        return f"unknown {self.kind} {name!r}; known: {', '.join(self.names())}"

    def get(self, name: str) -> T:
        """What ``name`` resolves to (imported or built on first use, then kept); raises
        ``unknown_error`` with :meth:`unknown`'s wording for a name nothing registers."""
        with self._lock:
            found = self._resolved.get(name)
            if found is not None:
                return found
            if name not in self._sources:
                raise self._unknown_error(self.unknown(name))
            source = self._sources[name]
        value = self._resolve(name, source)  # outside the lock: resolving may import modules
        if not self._keep:
            return value
        with self._lock:
            if self._sources.get(name) is source:  # not unregistered meanwhile
                value = self._resolved.setdefault(name, value)
        return value

    def _resolve(self, name: str, source: object) -> T:
        obj = self._import(source) if isinstance(source, str) else source
        if self._coerce is None:
            return obj  # type: ignore[return-value]  # T is object when nothing coerces
        return self._coerce(name, obj)

    def _import(self, reference: str) -> object:
        return import_reference(reference, self._attribute)

    def items(self) -> list[tuple[str, T]]:
        """``(name, resolved)`` pairs in registration order (resolves every entry)."""
        return [(name, self.get(name)) for name in self.names()]

    def values(self) -> list[T]:
        """The resolved entries in registration order (resolves every entry)."""
        return [self.get(name) for name in self.names()]

    # -- dict-like reading ---------------------------------------------------------------------
    def __getitem__(self, name: str) -> T:
        return self.get(name)

    def __contains__(self, name: object) -> bool:
        with self._lock:
            return name in self._sources

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def __len__(self) -> int:
        with self._lock:
            return len(self._sources)

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}: {', '.join(self.names())})"


def import_reference(reference: str, attribute: str | None = None) -> object:
    """What ``"package.module[:ATTRIBUTE]"`` names: the module's ``ATTRIBUTE`` (``attribute``
    when the reference names none), or the module itself when neither does."""
    module, _, named = reference.partition(":")
    named = named or attribute or ""
    loaded = importlib.import_module(module)
    return getattr(loaded, named) if named else loaded
