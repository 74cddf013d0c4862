"""Arrow schemas of the run tables, derived from the record dataclasses.

The schema of each table is the record's fields (in order) after a leading ``run_id`` column.
Deriving it from the dataclass keeps one definition of every column; the explicit type map
below pins the Arrow type of each Python annotation so files stay stable across versions.
"""

from __future__ import annotations

import dataclasses
import functools
import typing
from collections.abc import Iterator, Mapping
from typing import TYPE_CHECKING, Any

from schemas.records import ALL_RECORD_TYPES, SCHEMA_VERSION, NodeVersion

if TYPE_CHECKING:
    import pyarrow as pa


@functools.cache
def _pa() -> Any:
    """pyarrow, imported on first use. Why lazily: an episode worker only turns records into plain
    rows (:func:`record_to_row`) and never builds a schema; importing pyarrow (and numpy with it)
    there would cost every worker process ~30 MB for nothing (issue 37, item 3)."""
    import pyarrow

    return pyarrow


@functools.cache
def _node_version() -> pa.DataType:
    pa = _pa()
    return pa.struct(
        [
            pa.field("version", pa.int32(), nullable=False),
            pa.field("think", pa.string()),
            pa.field("subtasks", pa.list_(pa.string()), nullable=False),
            pa.field("call_index", pa.int32()),
            pa.field("message_seq", pa.int64()),
        ]
    )


def _scalar(annotation: Any) -> pa.DataType | None:
    pa = _pa()
    return {str: pa.string(), int: pa.int64(), float: pa.float64(), bool: pa.bool_(), bytes: pa.binary()}.get(annotation)


def _arrow_type(annotation: Any) -> tuple[pa.DataType, bool]:
    """Map a resolved annotation to (Arrow type, nullable)."""
    pa = _pa()
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    if origin is typing.Union or (origin is not None and str(origin) == "<class 'types.UnionType'>"):
        inner = [a for a in args if a is not type(None)]
        t, _ = _arrow_type(inner[0])
        return t, True
    if origin is tuple:
        item = args[0]
        if item is NodeVersion:
            return pa.list_(_node_version()), False
        return pa.list_(_arrow_type(item)[0]), False
    if origin is typing.Literal and args and all(isinstance(a, str) for a in args):
        return pa.string(), False  # a closed vocabulary (schemas.kinds) is stored as its string
    scalar = _scalar(annotation) if isinstance(annotation, type) else None
    if scalar is not None:
        return scalar, False
    raise TypeError(f"no Arrow type for {annotation!r}")


def _table_name(record_type: type) -> str:
    """The table a record type's rows go to (its ``table`` class attribute)."""
    return str(record_type.__dict__["table"])


def _schema_for(record_type: type) -> pa.Schema:
    pa = _pa()
    hints = typing.get_type_hints(record_type)
    fields = [pa.field("run_id", pa.string(), nullable=False)]
    for f in dataclasses.fields(record_type):
        t, nullable = _arrow_type(hints[f.name])
        fields.append(pa.field(f.name, t, nullable=nullable))
    return pa.schema(fields, metadata={b"recap_eval_schema_version": str(SCHEMA_VERSION).encode()})


class _Schemas(Mapping[str, "pa.Schema"]):
    """Table name -> Arrow schema, each built (and pyarrow imported) on first access; the names
    alone (``list(TABLES)``, ``in``) need no pyarrow."""

    def __init__(self, record_types: typing.Iterable[type]) -> None:
        self._types = {_table_name(rt): rt for rt in record_types}
        self._built: dict[str, pa.Schema] = {}

    def __getitem__(self, table: str) -> pa.Schema:
        if table not in self._built:
            self._built[table] = _schema_for(self._types[table])  # KeyError for an unknown table
        return self._built[table]

    def __iter__(self) -> Iterator[str]:
        return iter(self._types)

    def __len__(self) -> int:
        return len(self._types)


TABLES: Mapping[str, pa.Schema] = _Schemas(ALL_RECORD_TYPES)
#: tables whose rows are content-addressed and may be written more than once (two workers reading
#: the same page), by the columns naming one row (a record type's ``unique_by``): readers that
#: count rows see one per key
UNIQUE_BY: dict[str, tuple[str, ...]] = {
    _table_name(rt): tuple(rt.__dict__["unique_by"]) for rt in ALL_RECORD_TYPES if "unique_by" in rt.__dict__
}
_TYPE_OF_TABLE: dict[str, type] = {_table_name(rt): rt for rt in ALL_RECORD_TYPES}


def arrow_schema(table: str) -> pa.Schema:
    """The Arrow schema of ``table`` (KeyError names the known tables)."""
    try:
        return TABLES[table]
    except KeyError:
        raise KeyError(f"unknown table {table!r}; known: {sorted(TABLES)}") from None


def table_of(record: Any) -> str:
    """The table ``record`` belongs to."""
    return _table_name(type(record))


def record_type(table: str) -> type:
    """The record class of ``table``."""
    return _TYPE_OF_TABLE[table]


@functools.cache
def vocabularies(record_type: Any) -> dict[str, frozenset[str]]:
    """The closed-vocabulary fields of a record type (``Literal`` annotations, :mod:`schemas.kinds`)
    and the values each admits."""
    out: dict[str, frozenset[str]] = {}
    for name, hint in typing.get_type_hints(record_type).items():
        args = (
            [a for a in typing.get_args(hint) if a is not type(None)] if typing.get_origin(hint) is not typing.Literal else [hint]
        )
        for a in args:
            if typing.get_origin(a) is typing.Literal:
                out[name] = frozenset(typing.get_args(a))
    return out


class VocabularyError(ValueError):
    """A record names a kind, status or reason its table does not know (a writer's bug)."""


def check_vocabulary(record: Any) -> Any:
    """``record`` itself, after checking its closed-vocabulary fields: a value outside them raises
    :class:`VocabularyError`. The pipeline's writers of end reasons and event kinds call this, so a
    misspelt kind fails where it is made instead of being written and silently missing every
    report that filters on it. (Readers never check: rows of older versions stay readable.)"""
    allowed = vocabularies(type(record))  # type: ignore[arg-type]  # record classes hash by identity
    for name, values in allowed.items():
        value = getattr(record, name)
        if value is not None and value not in values:
            raise VocabularyError(f"{type(record).__name__}.{name}: {value!r} is not one of {sorted(values)}")
    return record


def record_to_row(record: Any, run_id: str) -> dict[str, Any]:
    """A record as a dict in its table's column order, ``run_id`` first."""
    row: dict[str, Any] = {"run_id": run_id}
    for f in dataclasses.fields(record):
        value = getattr(record, f.name)
        if f.name == "versions":
            value = [dataclasses.asdict(v) | {"subtasks": list(v.subtasks)} for v in value]
        elif isinstance(value, tuple):
            value = list(value)
        row[f.name] = value
    return row


def rows_to_table(table: str, rows: list[dict[str, Any]]) -> pa.Table:
    """Rows of ``table`` (dicts of its columns, ``run_id`` included) as an Arrow table with the
    table's pinned schema, so every part file of it has the same column types; pyarrow raises on a
    value that does not fit its column."""
    return _pa().Table.from_pylist(rows, schema=arrow_schema(table))
