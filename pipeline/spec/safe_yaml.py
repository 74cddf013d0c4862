"""The hardened reader of sweep files: a bounded regular file of UTF-8, then YAML without aliases, duplicate keys or huge values.

Every rule fails as one :class:`~pipeline.errors.SpecError` line that names the file and the
line in it, before any model call or write (the rules are listed in :mod:`pipeline.spec`).
"""

from __future__ import annotations

import math
import os
import stat
from pathlib import Path
from typing import Any

import yaml

from pipeline.errors import SpecError
from pipeline.spec.bounds import INT64_MAX, MAX_DEPTH, MAX_SCALAR_CHARS, MAX_SPEC_BYTES
from pipeline.spec.fields import field_path


class _Refused(Exception):
    """A YAML construct the sweep file may not use; the message names the line."""


def _line(node_or_event: yaml.Node | yaml.Event) -> int:
    mark = getattr(node_or_event, "start_mark", None)
    return mark.line + 1 if mark is not None else 0


_MERGE_TAG = "tag:yaml.org,2002:merge"


class _SpecLoader(yaml.SafeLoader):
    """SafeLoader that refuses anchors/aliases/merge keys, duplicate keys, huge scalars and deep
    nesting, each with the line it is on."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent: yaml.Node | None, index: object) -> yaml.Node | None:
        event = self.peek_event()
        if isinstance(event, yaml.AliasEvent):
            raise _Refused(f"YAML aliases are not allowed (*{event.anchor} at line {_line(event)}); write the value out")
        anchor = getattr(event, "anchor", None)
        if anchor is not None:
            raise _Refused(f"YAML anchors are not allowed (&{anchor} at line {_line(event)}); write the value out")
        if isinstance(event, yaml.ScalarEvent) and len(event.value) > MAX_SCALAR_CHARS:
            raise _Refused(f"a value of {len(event.value)} characters at line {_line(event)}; at most {MAX_SCALAR_CHARS}")
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                raise _Refused(f"nested deeper than {MAX_DEPTH} levels at line {_line(event)}")
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_mapping(self, node: yaml.Node, deep: bool = False) -> dict[Any, Any]:
        if isinstance(node, yaml.MappingNode):
            seen: dict[Any, int] = {}
            for key_node, _ in node.value:
                if key_node.tag == _MERGE_TAG:
                    raise _Refused(f"YAML merge keys (<<) are not allowed (line {_line(key_node)})")
                key = self.construct_object(key_node, deep=True)
                try:
                    first = seen.get(key)
                except TypeError:
                    raise _Refused(f"a mapping key at line {_line(key_node)} is not a plain value") from None
                if first is not None:
                    raise _Refused(f"duplicate key {key!r} at line {_line(key_node)} (first at line {first})")
                seen[key] = _line(key_node)
        return super().construct_mapping(node, deep=deep)

    def construct_yaml_int(self, node: yaml.ScalarNode) -> int:
        try:
            return super().construct_yaml_int(node)
        except ValueError:
            raise _Refused(f"integer {node.value[:20]!r}... at line {_line(node)} is too large") from None


_SpecLoader.add_constructor("tag:yaml.org,2002:int", _SpecLoader.construct_yaml_int)


def _check_values(data: Any, loc: tuple[Any, ...] = ()) -> None:
    """Every number in the file finite and within a signed 64-bit column (free-form mappings
    such as params, options and settings included); only plain JSON-like values (no dates,
    binary or sets, which would reach JSON columns and hashes as something else)."""
    if isinstance(data, dict):
        for k, v in data.items():
            _check_values(v, (*loc, k))
    elif isinstance(data, list):
        for i, v in enumerate(data):
            _check_values(v, (*loc, i))
    elif data is not None and not isinstance(data, (str, int, float)):
        raise _Refused(
            f"{field_path(loc) or 'value'}: a YAML {type(data).__name__} is not allowed here; quote it to make it a string"
        )
    elif isinstance(data, float) and not math.isfinite(data):
        raise _Refused(f"{field_path(loc) or 'value'}: must be a finite number, got {data}")
    elif isinstance(data, int) and not isinstance(data, bool) and not -INT64_MAX - 1 <= data <= INT64_MAX:
        raise _Refused(f"{field_path(loc) or 'value'}: integer out of range (-2**63 .. 2**63-1)")


def _check_events(text: str, loader: type[yaml.SafeLoader]) -> None:
    """One pass over the parser's events (libyaml's when there is one: fast): anchors, aliases,
    huge scalars and deep nesting are refused before anything is composed."""
    depth = 0
    for event in yaml.parse(text, Loader=loader):
        if isinstance(event, yaml.AliasEvent):
            raise _Refused(f"YAML aliases are not allowed (*{event.anchor} at line {_line(event)}); write the value out")
        anchor = getattr(event, "anchor", None)
        if anchor is not None:
            raise _Refused(f"YAML anchors are not allowed (&{anchor} at line {_line(event)}); write the value out")
        if isinstance(event, yaml.ScalarEvent) and len(event.value) > MAX_SCALAR_CHARS:
            raise _Refused(f"a value of {len(event.value)} characters at line {_line(event)}; at most {MAX_SCALAR_CHARS}")
        if isinstance(event, yaml.CollectionStartEvent):
            depth += 1
            if depth > MAX_DEPTH:
                raise _Refused(f"nested deeper than {MAX_DEPTH} levels at line {_line(event)}")
        elif isinstance(event, yaml.CollectionEndEvent):
            depth -= 1


#: malformed files up to this size are re-read by the (slower) pure-Python parser for its message
_PY_MESSAGE_MAX = 64 * 1024


def _yaml_data(text: str) -> Any:
    fast = getattr(yaml, "CSafeLoader", None)
    if fast is None:
        loader = _SpecLoader(text)
        try:
            return loader.get_single_data()
        finally:
            loader.dispose()
    try:
        _check_events(text, fast)
        node = yaml.compose(text, Loader=fast)
    except yaml.YAMLError:
        if len(text) > _PY_MESSAGE_MAX:
            raise
        # the pure-Python parser's message (and line) for the same problem: the one users know
        loader = _SpecLoader(text)
        try:
            loader.get_single_data()
        finally:
            loader.dispose()
        raise
    if node is None:
        return None
    constructor = _SpecLoader("")
    try:
        return constructor.construct_document(node)
    finally:
        constructor.dispose()


def load_yaml(text: str, source: str = "spec") -> Any:
    """The YAML data of a sweep file (see the module docstring for what is refused)."""
    if len(text) > MAX_SPEC_BYTES or len(text.encode("utf-8", "surrogatepass")) > MAX_SPEC_BYTES:
        raise SpecError(f"{source}: larger than {MAX_SPEC_BYTES} bytes; a sweep file may be at most 1 MiB")
    try:
        data = _yaml_data(text)
        _check_values(data)
        return data
    except _Refused as exc:
        raise SpecError(f"{source}: {exc}") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise SpecError(f"{source}: malformed YAML{where}: {problem}") from None
    except (ValueError, OverflowError, RecursionError, MemoryError) as exc:
        raise SpecError(f"{source}: malformed YAML: {type(exc).__name__}: {str(exc)[:200]}") from None


def read_spec_text(path: str | Path) -> str:
    """The text of a sweep file: a regular file of at most MAX_SPEC_BYTES of UTF-8. A device
    (``/dev/zero``), FIFO or socket is refused before it is read (or opened: a FIFO's open
    would block)."""
    p = Path(path)
    name = repr(str(p))
    try:
        st = os.stat(p)
    except (FileNotFoundError, NotADirectoryError):
        raise SpecError(f"sweep file {name} does not exist") from None
    except OSError as exc:
        raise SpecError(f"sweep file {name} cannot be read: {exc.strerror or exc}") from None
    if stat.S_ISDIR(st.st_mode):
        raise SpecError(f"sweep file {name} cannot be read: it is a folder")
    if not stat.S_ISREG(st.st_mode):
        raise SpecError(f"sweep file {name} cannot be read: not a regular file (a device, FIFO or socket)")
    if st.st_size > MAX_SPEC_BYTES:
        raise SpecError(f"sweep file {name} is {st.st_size} bytes; a sweep file may be at most 1 MiB")
    try:
        fd = os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as exc:
        raise SpecError(f"sweep file {name} cannot be read: {exc.strerror or exc}") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):  # swapped since the stat
            raise SpecError(f"sweep file {name} cannot be read: not a regular file (a device, FIFO or socket)")
        with os.fdopen(fd, "rb", closefd=False) as fh:
            raw = fh.read(MAX_SPEC_BYTES + 1)
    except OSError as exc:
        raise SpecError(f"sweep file {name} cannot be read: {exc.strerror or exc}") from None
    finally:
        os.close(fd)
    if len(raw) > MAX_SPEC_BYTES:
        raise SpecError(f"sweep file {name} is larger than {MAX_SPEC_BYTES} bytes; a sweep file may be at most 1 MiB")
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SpecError(
            f"sweep file {name} cannot be read: not UTF-8 text (byte {raw[exc.start]:#04x} at offset {exc.start})"
        ) from None
