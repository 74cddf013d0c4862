"""The gateway's batched ``llm_calls`` writer: a batch the periodic flush is writing when the
gateway closes is on disk when the close returns (the process may be killed right after).

This is the race behind a sweep whose capped gateway lost all its rows: close cancelled the
flusher while its thread was writing, returned at once, and ``ray.kill`` ended the thread."""

from __future__ import annotations

import asyncio
import threading
import time

import pyarrow.parquet as pq

from schemas.records import CallRecord
from workers.gateway.call_log import CallLog


def _record(i: int) -> CallRecord:
    return CallRecord(
        episode_id="u1-1", call_index=i, call_key=f"u1-1#{i}", purpose="task", window_seqs=(), model="m", status="ok"
    )


def test_closing_while_the_periodic_flush_writes_waits_for_that_batch(tmp_path, monkeypatch):
    log = CallLog(tmp_path, "r1", "gw-test", flush_interval_s=0.01)
    writing = threading.Event()
    real = log._writer.write_rows

    def slow_write(table, rows):  # the disk is slow: the batch is still being written at close
        writing.set()
        time.sleep(0.5)
        return real(table, rows)

    monkeypatch.setattr(log._writer, "write_rows", slow_write)

    async def go() -> int:
        flusher = asyncio.create_task(log.run_periodic_flush())
        log.add(_record(0))
        log.add(_record(1))
        while not writing.is_set():
            await asyncio.sleep(0.005)
        flusher.cancel()  # what the gateway's close does
        try:
            await flusher
        except asyncio.CancelledError:
            pass
        return log.rows_written  # read the moment the close would return

    assert asyncio.run(go()) == 2
    rows = pq.read_table(tmp_path / "llm_calls").to_pylist()
    assert sorted((r["call_key"], r["run_id"]) for r in rows) == [("u1-1#0", "r1"), ("u1-1#1", "r1")]


def test_rows_added_after_the_last_periodic_batch_are_written_by_the_final_flush(tmp_path):
    log = CallLog(tmp_path, "r1", "gw-test", flush_interval_s=60)

    async def go() -> None:
        flusher = asyncio.create_task(log.run_periodic_flush())
        await asyncio.sleep(0)
        log.add(_record(0))
        flusher.cancel()
        try:
            await flusher
        except asyncio.CancelledError:
            pass

    asyncio.run(go())
    assert log.rows_written == 1 and log.pending == 0
