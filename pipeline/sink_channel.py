"""The driver's side of the sink actor: hand rows over, keep them until acknowledged, and write
them itself when the sink is gone for good.

Why its own object: the sink (:mod:`workers.sink`) logs every batch before acknowledging it and
is restartable, so a killed sink loses nothing; the driver still has to keep each of its own
batches (the terminal ``episodes`` rows above all) until the sink acknowledges it, notice a sink
whose restarts are used up, recover what the dead sink had logged, and write the rest straight
into the run folder. None of that depends on how units are scheduled.
"""

from __future__ import annotations

import logging
import time
import uuid
from pathlib import Path
from typing import Any

from pipeline.events import EventBuffer
from schemas.parts import PartWriter
from workers.sink import batch_hash, records_by_table, recover_wal, sink_actor

Rows = dict[str, list[dict[str, Any]]]

log = logging.getLogger(__name__)


class SinkLost(Exception):
    """The sink actor is gone for good (its restarts used up) or does not answer."""


class SinkChannel:
    """Rows from the driver to the sink actor (or, once it is lost, to the run folder)."""

    #: how long the driver waits on the sink (a restart included) before it counts it as lost
    WAIT_S = 120.0

    def __init__(self, run_dir: Path, run_id: str, events: EventBuffer, *, session: str) -> None:
        self.run_dir = Path(run_dir)
        self.run_id = run_id
        self.events = events
        self.session = session
        self.actor: Any = None
        #: the sink's writer name: fixed for the session, so a restarted sink finds its log
        self.writer = f"sink{uuid.uuid4().hex[:10]}"
        #: (ref, batch hash, rows) of the driver's batches the sink has not acknowledged yet
        self._unacked: list[tuple[Any, str, Rows]] = []
        #: why the sink is gone for good (None while it lives)
        self.lost: str | None = None

    def start(self, node_id: str) -> Any:
        """The sink actor, pinned to this node (the run folder is local to it)."""
        from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy  # lazy: Ray loads only where a session uses it

        here = NodeAffinitySchedulingStrategy(node_id=node_id, soft=False)
        self.actor = sink_actor().options(scheduling_strategy=here).remote(str(self.run_dir), self.run_id, writer=self.writer)
        return self.actor

    def send(self, records: list[Any], *, flush: bool = False) -> None:
        """Hand rows to the sink (kept until it acknowledges them); straight to the run folder
        once the sink is lost."""
        if not records:
            return

        rows = records_by_table(records, self.run_id)
        if self.lost is not None or self.actor is None:
            self.write_direct([rows])
            return
        ref = self.actor.add.remote(rows, flush=flush)
        self._unacked.append((ref, batch_hash(rows), rows))

    def maybe_flush(self) -> None:
        """Ask the sink to write its buffers if they are due (fire and forget); nothing once the sink is lost."""
        if self.actor is not None and self.lost is None:
            self.actor.maybe_flush.remote()

    def check_acks(self, timeout: float | None = 0.0) -> None:
        """Drop the batches the sink acknowledged; raise :class:`SinkLost` when one failed
        (or, with a timeout, when not all were acknowledged in time)."""
        import ray  # lazy: Ray loads only where a session uses it
        from ray.exceptions import RayActorError

        if not self._unacked or self.lost is not None:
            return
        refs = [r for r, _, _ in self._unacked]
        ready, _ = ray.wait(refs, num_returns=len(refs), timeout=timeout)
        done = set(ready)
        keep, failed = [], None
        for item in self._unacked:
            if item[0] not in done:
                keep.append(item)
                continue
            try:
                ray.get(item[0])
            except RayActorError as exc:
                failed = failed or f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
                keep.append(item)
            except Exception as exc:  # the sink could not log or write them (a full disk ...)
                failed = failed or f"{type(exc).__name__}: {str(exc).splitlines()[-1] if str(exc) else ''}"
                keep.append(item)
        self._unacked = keep
        if failed:
            raise SinkLost(f"the sink failed: {failed}")
        if timeout and keep:
            raise SinkLost(f"the sink did not acknowledge {len(keep)} batches within {timeout:.0f}s")

    def gone(self) -> str | None:
        """Why the sink is gone for good, or None when it answers (after a restart if need be)."""
        import ray  # lazy: Ray loads only where a session uses it
        from ray.exceptions import GetTimeoutError, RayActorError

        if self.lost is not None:
            return self.lost
        try:
            ray.get(self.actor.ping.remote(), timeout=self.WAIT_S)
            return None
        except GetTimeoutError:
            return f"the sink did not answer within {self.WAIT_S:.0f}s"
        except RayActorError as exc:
            return f"the sink died: {type(exc).__name__}"

    def on_lost(self, why: str) -> None:
        """The sink is gone: write what its log holds and every batch of the driver it never
        took (the terminal rows above all) straight into the run folder."""
        import ray  # lazy: Ray loads only where a session uses it

        if self.lost is not None:
            return
        self.lost = why
        log.error("the sink is gone (%s): writing its log and the driver's batches into %s directly", why, self.run_dir)
        try:
            ray.kill(self.actor, no_restart=True)
        except Exception:
            pass
        time.sleep(1.0)  # its process gone before its log is read
        found = recover_wal(self.run_dir, self.writer)
        pending = [rows for _, h, rows in self._unacked if h not in found.hashes]
        self._unacked = []
        self.events.add("sink_lost", severity="error", reason=why, recovered_rows=found.rows, driver_batches=len(pending))
        self.write_direct(pending)

    def write_direct(self, batches: list[Rows]) -> None:
        """Rows written by the driver itself (the sink is lost): pending events first,
        terminal rows last."""
        if self.events:
            batches = [records_by_table(self.events.drain(), self.run_id)] + list(batches)
        merged: Rows = {}
        for rows in batches:
            for table, r in rows.items():
                merged.setdefault(table, []).extend(r)
        if not merged:
            return
        writer = PartWriter(self.run_dir, f"driver{self.session}{uuid.uuid4().hex[:6]}")
        for table in sorted(merged, key=lambda t: (t == "episodes", t)):
            writer.write_rows(table, merged[table])

    def close(self) -> None:
        """Every driver batch acknowledged, the buffers written, the sink's log removed."""
        import ray  # lazy: Ray loads only where a session uses it
        from ray.exceptions import GetTimeoutError, RayActorError

        if self.actor is None or self.lost is not None:
            return
        try:
            self.check_acks(timeout=self.WAIT_S)
            ray.get(self.actor.close.remote(), timeout=self.WAIT_S)
        except SinkLost as exc:
            self.on_lost(str(exc))
        except (RayActorError, GetTimeoutError) as exc:
            self.on_lost(f"the sink failed at the end of the session: {type(exc).__name__}")

    def kill(self) -> None:
        """End the sink actor at the end of the session (after :meth:`close`); errors are ignored, the rows are already safe."""
        if self.actor is not None:
            import ray  # lazy: Ray loads only where a session uses it

            try:
                ray.kill(self.actor)
            except Exception:
                pass
