"""Arrow schemas and record types shared by every layer.

Everything that is written to disk passes through one of the record dataclasses in
:mod:`schemas.records`; :mod:`schemas.tables` maps each to an Arrow schema. Both carry
``SCHEMA_VERSION`` so that a reader can refuse (or migrate) a run written by another version.
"""

from schemas.records import (
    SCHEMA_VERSION,
    CallRecord,
    EpisodeRecord,
    EvaluationRecord,
    EventRecord,
    MessageRecord,
    NodeRecord,
    NodeVersion,
    Record,
    RunRecord,
    StepRecord,
    ToolCallRecord,
)
from schemas.tables import TABLES, arrow_schema, record_to_row, table_of

__all__ = [
    "SCHEMA_VERSION",
    "CallRecord",
    "EpisodeRecord",
    "EvaluationRecord",
    "EventRecord",
    "MessageRecord",
    "NodeRecord",
    "NodeVersion",
    "Record",
    "RunRecord",
    "StepRecord",
    "ToolCallRecord",
    "TABLES",
    "arrow_schema",
    "record_to_row",
    "table_of",
]
