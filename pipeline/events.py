"""The driver's ``events`` rows, buffered until the next shipment to the sink.

Why a buffer object: the session, the cap policy and the sink channel all record events (a cap
reached, a worker restarted, the sink lost); they share this one buffer so the rows leave in the
order they happened, and the sink channel can take whatever is pending when it must write
straight to the run folder.
"""

from __future__ import annotations

import json
import logging
import time
from typing import Any

from schemas.kinds import EventKind, EventSource, Severity
from schemas.records import EventRecord
from schemas.tables import check_vocabulary

log = logging.getLogger(__name__)


class EventBuffer:
    """Driver events not yet handed to the sink."""

    def __init__(self, source: EventSource = "driver") -> None:
        self.source = source
        self._events: list[EventRecord] = []

    def add(
        self,
        kind: EventKind,
        *,
        severity: Severity = "info",
        unit_id: str | None = None,
        episode_id: str | None = None,
        **detail: Any,
    ) -> None:
        """Record one event now (and log it); ``detail`` keyword arguments become the row's JSON ``detail``. The
        kind and severity are checked against the closed vocabularies."""
        log.info(
            "event %s (%s)%s%s %s",
            kind,
            severity,
            f" unit {unit_id}" if unit_id else "",
            f" episode {episode_id}" if episode_id else "",
            detail,
        )
        self._events.append(
            check_vocabulary(
                EventRecord(
                    ts=time.time(),
                    source=self.source,
                    kind=kind,
                    severity=severity,
                    episode_id=episode_id,
                    unit_id=unit_id,
                    detail=json.dumps(detail, sort_keys=True, default=str),
                )
            )
        )

    def drain(self) -> list[EventRecord]:
        """Every pending event, oldest first; the buffer is empty afterwards."""
        events, self._events = self._events, []
        return events

    def __len__(self) -> int:
        return len(self._events)

    def __bool__(self) -> bool:
        return bool(self._events)
